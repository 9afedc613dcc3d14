//! Files the tool writes: atomic replacement (through temporary files that a later run
//! can recognise and remove), checks of output paths before any work, and the CSV
//! state dump.

use std::io::{BufWriter, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::Path;

use anyhow::{Context, bail};

use crate::sim::Particles;

/// Temporary files are named `.collide-XXXXXX.partial`: hidden, never `.parquet` (so no
/// reader takes one for results), and recognisable by [`remove_leftovers`].
const TEMP_PREFIX: &str = ".collide-";
const TEMP_SUFFIX: &str = ".partial";

/// Writes a file through a temporary sibling and renames it into place, so readers
/// never see a half-written file and a failure leaves any earlier file untouched.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> anyhow::Result<()> {
    let dir = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    };
    let temp = tempfile::Builder::new()
        .prefix(TEMP_PREFIX)
        .suffix(TEMP_SUFFIX)
        .tempfile_in(dir)
        .with_context(|| {
            format!(
                "cannot create a file in {}; check that the directory exists and is writable",
                dir.display()
            )
        })?;
    {
        let mut writer = BufWriter::new(temp.as_file());
        write(&mut writer).and_then(|()| writer.flush())
    }
    .with_context(|| format!("cannot write {}", path.display()))?;
    // Temporary files are private (0600); a finished result is an ordinary file.
    temp.as_file()
        .set_permissions(std::fs::Permissions::from_mode(0o644))
        .with_context(|| format!("cannot make {} readable", path.display()))?;
    // The persist error's text is its I/O error's: keep only the I/O error, said once.
    temp.persist(path)
        .map_err(|failed| failed.error)
        .with_context(|| format!("cannot move the finished file to {}", path.display()))?;
    Ok(())
}

/// Removes the temporary files that writers killed before their rename left in `dir`
/// (not below it); returns how many. Call only while no other writer uses `dir`.
pub fn remove_leftovers(dir: &Path) -> anyhow::Result<usize> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(0);
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with(TEMP_PREFIX) && name.ends_with(TEMP_SUFFIX) {
            let path = entry.path();
            std::fs::remove_file(&path)
                .with_context(|| format!("cannot remove the unfinished file {}", path.display()))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Checks, before any work, that a file can be written at `path`: its folder exists and
/// is a folder, and `path` is not a folder. `flag` names where the path came from.
pub fn check_output_file(path: &Path, flag: &str) -> anyhow::Result<()> {
    if path.is_dir() {
        bail!(
            "{flag} {} is a folder; give a file name, e.g. {}",
            path.display(),
            path.join("out").display()
        );
    }
    let dir = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    };
    match std::fs::metadata(dir) {
        // The probe file is removed when dropped.
        Ok(meta) if meta.is_dir() => match tempfile::Builder::new()
            .prefix(TEMP_PREFIX)
            .suffix(TEMP_SUFFIX)
            .tempfile_in(dir)
        {
            Ok(_) => Ok(()),
            Err(err) => bail!(
                "{flag} {}: cannot write in the folder {} ({}); choose another path",
                path.display(),
                dir.display(),
                io_reason(&err)
            ),
        },
        Ok(_) => bail!(
            "{flag} {}: {} is a file, not a folder; choose a path in an existing folder",
            path.display(),
            dir.display()
        ),
        Err(err) => bail!(
            "{flag} {}: cannot use the folder {} ({}); create it first or choose another path",
            path.display(),
            dir.display(),
            io_reason(&err)
        ),
    }
}

/// An I/O error's reason in words, without the OS error number.
pub fn io_reason(err: &std::io::Error) -> String {
    without_os_code(err.to_string())
}

/// `text` without the " (os error N)" that Rust appends to an I/O error's words.
pub fn without_os_code(text: String) -> String {
    match text.find(" (os error") {
        Some(end) => text[..end].to_owned(),
        None => text,
    }
}

/// The state as CSV, header `id,x,y,vx,vy,radius,mass`, one row per disk in id order.
/// Numbers are printed in Rust's shortest round-trip form, so they read back to the same bits.
pub fn write_state_csv(out: &mut dyn Write, particles: &Particles) -> std::io::Result<()> {
    writeln!(out, "id,x,y,vx,vy,radius,mass")?;
    for (id, disk) in particles.disks_by_id().iter().enumerate() {
        writeln!(
            out,
            "{id},{},{},{},{},{},{}",
            disk.x, disk.y, disk.vx, disk.vy, disk.radius, disk.mass
        )?;
    }
    Ok(())
}
