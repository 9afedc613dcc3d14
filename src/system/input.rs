//! Files the tool reads (manifests, scene files, baselines): regular files only, up to a
//! size stated before anything is allocated, so `/dev/zero`, a FIFO or a huge file is
//! refused in words instead of filling memory or blocking forever.

use std::io::Read;
use std::path::Path;

use crate::system::output::io_reason;

/// The largest text input read: a scene listing 10⁶ disks one per line is about 100 MB.
pub const MAX_TEXT_BYTES: u64 = 256 << 20;

/// The text of the regular file at `path` (links followed), if it is one, holds at most
/// `max_bytes` bytes and is UTF-8; otherwise why not and what to do, in words (without
/// the path, which the caller names).
pub fn read_text(path: &Path, max_bytes: u64) -> Result<String, String> {
    let unreadable = |err: std::io::Error| format!("{}; check the path", io_reason(&err));
    let meta = std::fs::metadata(path).map_err(unreadable)?;
    if !meta.is_file() {
        return Err(format!(
            "it is a {}, not a regular file; give the path of a file",
            kind_of(&meta)
        ));
    }
    if meta.len() > max_bytes {
        return Err(format!(
            "it holds {} bytes, more than the {max_bytes} collide reads from such a file; \
             give a smaller file",
            meta.len()
        ));
    }
    let file = std::fs::File::open(path).map_err(unreadable)?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    // The file may grow between the size check and the read: never read past the cap.
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(unreadable)?;
    if bytes.len() as u64 > max_bytes {
        return Err(format!(
            "it grew past the {max_bytes} bytes collide reads from such a file while being read"
        ));
    }
    String::from_utf8(bytes).map_err(|err| {
        format!(
            "it is not UTF-8 text (invalid bytes at byte {}); save it as UTF-8",
            err.utf8_error().valid_up_to()
        )
    })
}

/// What kind of file `meta` describes, in words.
pub fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let kind = meta.file_type();
    if kind.is_dir() {
        "folder"
    } else if kind.is_fifo() {
        "named pipe (FIFO)"
    } else if kind.is_char_device() {
        "character device"
    } else if kind.is_block_device() {
        "block device"
    } else if kind.is_socket() {
        "socket"
    } else {
        "regular file"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_pipes_folders_and_large_files_are_refused_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let zero = read_text(Path::new("/dev/zero"), MAX_TEXT_BYTES).unwrap_err();
        assert!(zero.contains("character device"), "{zero}");
        let folder = read_text(dir.path(), MAX_TEXT_BYTES).unwrap_err();
        assert!(folder.contains("folder"), "{folder}");
        let fifo = dir.path().join("fifo");
        make_fifo(&fifo);
        let pipe = read_text(&fifo, MAX_TEXT_BYTES).unwrap_err();
        assert!(pipe.contains("named pipe"), "{pipe}");
        let big = dir.path().join("big.toml");
        std::fs::write(&big, "x".repeat(100)).unwrap();
        let large = read_text(&big, 10).unwrap_err();
        assert!(large.contains("100 bytes"), "{large}");
        assert_eq!(read_text(&big, 100).unwrap().len(), 100);
        std::fs::write(&big, [b'a', 0xff, b'b']).unwrap();
        let binary = read_text(&big, 100).unwrap_err();
        assert!(binary.contains("not UTF-8"), "{binary}");
    }

    fn make_fifo(path: &Path) {
        use std::os::unix::ffi::OsStrExt;
        let name = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
        // SAFETY: `name` is a valid NUL-terminated path that outlives the call.
        assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
    }
}
