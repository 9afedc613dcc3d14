//! What commands print on standard output, written so that printing can never be what
//! stops a command: a closed reader (`collide results DIR | head -1`) ends the printing
//! quietly while the command finishes its files and keeps its exit code, as a Unix tool
//! does; any other failure (a full `/dev/full`) is kept and said in words at the end by
//! `main`. Use [`outln!`](crate::outln) and [`out!`](crate::out) instead of `println!`
//! and `print!`, which panic on a closed pipe.

use std::io::{ErrorKind, Write};
use std::sync::{Mutex, PoisonError};

/// How standard output has fared so far.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Stdout {
    /// Everything printed was written.
    Open,
    /// The reader went away (a closed pipe): nothing more is printed, and that is fine.
    Closed,
    /// Writing failed for another reason, in words: the command reports it at the end.
    Failed(String),
}

static STATE: Mutex<Stdout> = Mutex::new(Stdout::Open);

/// Writes `text` to standard output unless an earlier write failed; a failure is
/// recorded in [`state`], never raised.
pub fn write(text: std::fmt::Arguments<'_>) {
    let mut state = STATE.lock().unwrap_or_else(PoisonError::into_inner);
    if *state != Stdout::Open {
        return;
    }
    let mut stdout = std::io::stdout().lock();
    if let Err(err) = stdout.write_fmt(text).and_then(|()| stdout.flush()) {
        *state = match err.kind() {
            ErrorKind::BrokenPipe => Stdout::Closed,
            ErrorKind::StorageFull => Stdout::Failed(
                "cannot print to standard output: no space left on the device it writes to"
                    .to_owned(),
            ),
            _ => Stdout::Failed(format!(
                "cannot print to standard output: {}",
                crate::system::output::io_reason(&err)
            )),
        };
    }
}

/// How standard output has fared so far.
pub fn state() -> Stdout {
    STATE.lock().unwrap_or_else(PoisonError::into_inner).clone()
}

/// `print!` that never panics: see [`write`].
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => { $crate::system::console::write(format_args!($($arg)*)) };
}

/// `println!` that never panics: see [`write`].
#[macro_export]
macro_rules! outln {
    () => { $crate::system::console::write(format_args!("\n")) };
    ($($arg:tt)*) => {
        $crate::system::console::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}
