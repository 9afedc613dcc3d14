//! The exit codes of `collide`, declared once: `main` maps each outcome to its code, the
//! interrupt handler exits with [`INTERRUPTED`], and `--help` prints [`help`].

/// One exit code and what it means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Code {
    pub code: u8,
    pub meaning: &'static str,
}

pub const DONE: Code = Code {
    code: 0,
    meaning: "done: every run measured, no regression",
};
pub const RUNS_FAILED: Code = Code {
    code: 1,
    meaning: "it ran, but runs failed or timed out (their rows say why), \
              or `collide check` found a regression",
};
pub const ERROR: Code = Code {
    code: 2,
    meaning: "bad input or an I/O error: nothing was measured",
};
pub const INTERRUPTED: Code = Code {
    code: 130,
    meaning: "interrupted (Ctrl-C, SIGTERM): the runs that finished are kept",
};
/// Every code, in order.
pub const ALL: [Code; 4] = [DONE, RUNS_FAILED, ERROR, INTERRUPTED];

/// The table `--help` ends with.
pub fn help() -> String {
    let mut text = String::from("Exit codes:");
    for Code { code, meaning } in ALL {
        text.push_str(&format!("\n  {code:<4} {meaning}"));
    }
    text
}

/// An error after which runs were measured and recorded, but some failed: exit code
/// [`RUNS_FAILED`], not [`ERROR`].
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct RunsFailed(pub String);
