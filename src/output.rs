//! Files the tool writes: atomic replacement, and the CSV state dump.

use std::io::{BufWriter, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::Path;

use anyhow::Context;

use crate::sim::Particles;

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
    let temp = tempfile::NamedTempFile::new_in(dir).with_context(|| {
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
    temp.persist(path)
        .with_context(|| format!("cannot move the finished file to {}", path.display()))?;
    Ok(())
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
