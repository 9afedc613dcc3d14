//! Files the tool writes: atomic replacement (every output goes through it, by
//! temporary files that a later run can recognise and remove), checks of output paths
//! before any work, errors that say in words what went wrong and where (a full disk as
//! such), PNG and GIF pictures encoded from memory, and the CSV state dump.

use std::io::{BufWriter, ErrorKind, Write};
use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

use anyhow::{Context, anyhow, bail};
use plotters::coord::Shift;
use plotters::prelude::{BitMapBackend, DrawingArea, IntoDrawingArea};

use crate::sim::Particles;

/// Temporary files are named `.collide-XXXXXX.partial`: hidden, never `.parquet` (so no
/// reader takes one for results), and recognisable by [`remove_leftovers`].
const TEMP_PREFIX: &str = ".collide-";
const TEMP_SUFFIX: &str = ".partial";

/// A picture being drawn, in memory (RGB).
pub type Canvas<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// `<dir>/<base>.<ext>`, or the first of `<base>-2.<ext>`, `<base>-3.<ext>`, ... that
/// does not exist yet: a new file's name that takes no earlier file's place.
pub fn free_path(dir: &Path, base: &str, ext: &str) -> PathBuf {
    (1..)
        .map(|count| match count {
            1 => dir.join(format!("{base}.{ext}")),
            _ => dir.join(format!("{base}-{count}.{ext}")),
        })
        .find(|path| !path.exists())
        .expect("a free name among unboundedly many")
}

/// Writes a file through a temporary sibling and renames it into place, so readers
/// never see a half-written file and a failure leaves any earlier file untouched. Only a
/// regular file is ever replaced: a symbolic link is followed and its target replaced; a
/// character device or a FIFO (`/dev/null`, a named pipe) is written through; anything
/// else is refused (see [`Destination`]).
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> anyhow::Result<()> {
    let target = match Destination::of(path)? {
        Destination::File(target) => target,
        Destination::Stream => return write_through(path, write),
    };
    let dir = folder_of(&target);
    let temp = tempfile::Builder::new()
        .prefix(TEMP_PREFIX)
        .suffix(TEMP_SUFFIX)
        .tempfile_in(dir)
        .map_err(|err| {
            described(
                err,
                format!(
                    "cannot create a file in {}; check that the directory exists and is writable",
                    dir.display()
                ),
                dir,
            )
        })?;
    let _removed_if_interrupted = InFlight::register(temp.path());
    {
        let mut writer = BufWriter::new(temp.as_file());
        write(&mut writer).and_then(|()| writer.flush())
    }
    .map_err(|err| described(err, format!("cannot write {}", path.display()), dir))?;
    // Temporary files are private (0600); a finished result is an ordinary file.
    temp.as_file()
        .set_permissions(std::fs::Permissions::from_mode(0o644))
        .with_context(|| format!("cannot make {} readable", path.display()))?;
    temp.persist(&target).map_err(|err| {
        described(
            err.error,
            format!("cannot move the finished file to {}", path.display()),
            dir,
        )
    })?;
    Ok(())
}

/// Writes into an existing device or FIFO as it is: no temporary file, no rename.
fn write_through(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> anyhow::Result<()> {
    let stream = std::fs::OpenOptions::new()
        .write(true)
        .open(path)
        .with_context(|| format!("cannot open {} for writing", path.display()))?;
    let mut writer = BufWriter::new(stream);
    write(&mut writer)
        .and_then(|()| writer.flush())
        .map_err(|err| match err.kind() {
            ErrorKind::StorageFull | ErrorKind::QuotaExceeded => anyhow!(
                "cannot write {}: it is full (no space left on the device); write to another \
                 path",
                path.display()
            ),
            _ => anyhow::Error::new(err).context(format!("cannot write {}", path.display())),
        })
}

/// The folder a file lies in (`.` for a bare file name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    }
}

/// Where writing to an output path leads, once symbolic links are followed.
#[derive(Debug, PartialEq, Eq)]
enum Destination {
    /// A regular file, existing or not, at this path (the link's target for a link):
    /// replaced atomically.
    File(PathBuf),
    /// An existing character device or FIFO: written through, never replaced.
    Stream,
}

/// Links followed before a chain of them is taken for a loop (Linux's own limit).
const MAX_LINKS: usize = 40;

impl Destination {
    fn of(path: &Path) -> anyhow::Result<Destination> {
        let target = follow_links(path)?;
        let Ok(meta) = std::fs::metadata(&target) else {
            return Ok(Destination::File(target));
        };
        let kind = meta.file_type();
        if kind.is_file() {
            Ok(Destination::File(target))
        } else if kind.is_char_device() || kind.is_fifo() {
            Ok(Destination::Stream)
        } else if kind.is_dir() {
            bail!(
                "{} is a folder; give a file name, e.g. {}",
                path.display(),
                path.join("out").display()
            )
        } else {
            bail!(
                "{} is a {}, not a regular file; collide writes only regular files, character \
                 devices and named pipes: choose another path",
                path.display(),
                if kind.is_block_device() {
                    "block device"
                } else {
                    "socket"
                }
            )
        }
    }
}

/// `path` with every symbolic link along its last component followed (a dangling link
/// leads to the file it names, which writing creates).
fn follow_links(path: &Path) -> anyhow::Result<PathBuf> {
    let mut current = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match std::fs::symlink_metadata(&current) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let target = std::fs::read_link(&current)
                    .with_context(|| format!("cannot read the link {}", current.display()))?;
                current = folder_of(&current).join(target);
            }
            _ => return Ok(current),
        }
    }
    bail!(
        "{}: more than {MAX_LINKS} symbolic links in a row (a loop?); give the file's own path",
        path.display()
    )
}

/// Temporary files being written now: an interrupt removes them before exiting
/// ([`remove_in_flight`]), so an interrupted writer leaves nothing behind.
static IN_FLIGHT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// A temporary file registered in [`IN_FLIGHT`] for as long as this guard lives.
struct InFlight(PathBuf);

impl InFlight {
    fn register(path: &Path) -> InFlight {
        in_flight().push(path.to_path_buf());
        InFlight(path.to_path_buf())
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        in_flight().retain(|path| *path != self.0);
    }
}

fn in_flight() -> MutexGuard<'static, Vec<PathBuf>> {
    IN_FLIGHT.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Removes the temporary files of writes still in progress; for the interrupt handler,
/// just before the process exits.
pub fn remove_in_flight() {
    for path in in_flight().drain(..) {
        let _ = std::fs::remove_file(path);
    }
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

/// Checks, before any work, that a file can be written at `path`: it is not a folder
/// nor a kind of file collide never writes (see [`Destination`]), and the folder its
/// file (a link's target) goes in exists and may be written in. `flag` names where the
/// path came from.
pub fn check_output_file(path: &Path, flag: &str) -> anyhow::Result<()> {
    let target = match Destination::of(path).map_err(|err| anyhow!("{flag} {err:#}"))? {
        Destination::File(target) => target,
        Destination::Stream => return Ok(()),
    };
    let dir = folder_of(&target);
    if let Err(err) = std::fs::metadata(dir) {
        let through = match target == path {
            true => String::new(),
            false => format!(" (the link leads to {})", target.display()),
        };
        bail!(
            "{flag} {}{through}: cannot use the folder {} ({}); create it first or choose \
             another path",
            path.display(),
            dir.display(),
            io_reason(&err)
        );
    }
    check_writable_folder(
        dir,
        path,
        flag,
        "choose a path in a folder you may write in",
    )
}

/// Who a path is, to tell whether two paths name one file: the device and inode of an
/// existing file, or the absolute path a new file would get.
#[derive(Debug, PartialEq, Eq)]
enum Identity {
    Existing { device: u64, inode: u64 },
    New(PathBuf),
}

impl Identity {
    fn of(path: &Path) -> Identity {
        match std::fs::metadata(path) {
            Ok(meta) => Identity::Existing {
                device: meta.dev(),
                inode: meta.ino(),
            },
            Err(_) => {
                let target = follow_links(path).unwrap_or_else(|_| path.to_path_buf());
                let dir = std::fs::canonicalize(folder_of(&target))
                    .unwrap_or_else(|_| folder_of(&target).to_path_buf());
                Identity::New(dir.join(target.file_name().unwrap_or_default()))
            }
        }
    }
}

/// Refuses, before any work, an output that is one of the command's inputs or another of
/// its outputs (by the file they name, links followed): writing it would destroy the
/// input, or one output would silently take the other's place. Character devices
/// (`/dev/null`) may take several outputs. Each path comes with the flag or argument
/// that gave it.
pub fn check_distinct(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> anyhow::Result<()> {
    let is_device =
        |path: &Path| std::fs::metadata(path).is_ok_and(|meta| meta.file_type().is_char_device());
    for (index, &(flag, path)) in outputs.iter().enumerate() {
        if is_device(path) {
            continue;
        }
        let identity = Identity::of(path);
        if let Some((input, _)) = inputs.iter().find(|(_, p)| Identity::of(p) == identity) {
            bail!(
                "{flag} {} is the {input} itself: writing it would destroy the input; choose \
                 another path",
                path.display()
            );
        }
        if let Some((other, _)) = outputs[..index]
            .iter()
            .find(|(_, p)| Identity::of(p) == identity)
        {
            bail!(
                "{flag} {} is the same file as {other}: one would replace the other; give each \
                 output its own path",
                path.display()
            );
        }
    }
    Ok(())
}

/// Checks that `dir`, which exists, is a folder this process may write into; the error
/// names `path` (what the user gave, in or below `dir`), `flag` and `fix`.
fn check_writable_folder(dir: &Path, path: &Path, flag: &str, fix: &str) -> anyhow::Result<()> {
    if !dir.is_dir() {
        bail!(
            "{flag} {}: {} is a file, not a folder; {fix}",
            path.display(),
            dir.display()
        );
    }
    probe_write(dir).map_err(|err| {
        anyhow::anyhow!(
            "{flag} {}: cannot write in the folder {} ({}); {fix}",
            path.display(),
            dir.display(),
            io_reason(&err)
        )
    })
}

/// Whether this process may create a file in the folder `dir`: a probe file, removed
/// again at once (when dropped), named as the leftovers of writers are.
fn probe_write(dir: &Path) -> std::io::Result<()> {
    tempfile::Builder::new()
        .prefix(TEMP_PREFIX)
        .suffix(TEMP_SUFFIX)
        .tempfile_in(dir)
        .map(drop)
}

/// Checks, before any work, that a folder can be made (or is already) at `dir`, without
/// making it: the nearest part of the path that exists is a folder this process may
/// write into. `flag` names where the path came from.
pub fn check_output_folder(dir: &Path, flag: &str) -> anyhow::Result<()> {
    let existing = dir
        .ancestors()
        .map(|part| match part.as_os_str().is_empty() {
            true => Path::new("."),
            false => part,
        })
        .find(|part| part.symlink_metadata().is_ok())
        .unwrap_or(Path::new("."));
    if !existing.exists() {
        let target = std::fs::read_link(existing).unwrap_or_default();
        bail!(
            "{flag} {}: {} is a link to {}, which does not exist; create that folder first, \
             or choose another folder",
            dir.display(),
            existing.display(),
            target.display()
        );
    }
    check_writable_folder(existing, dir, flag, "choose another folder")
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

/// An I/O error as a sentence: `what` failed, and why; a full disk (or quota) is said
/// as such, with the folder whose disk it is, and the fix.
fn described(err: std::io::Error, what: String, dir: &Path) -> anyhow::Error {
    match err.kind() {
        ErrorKind::StorageFull | ErrorKind::QuotaExceeded => anyhow!(
            "{what}: the disk holding {} is full (no space left, or over quota); nothing was \
             written there; free some space, or write to another folder",
            dir.display()
        ),
        _ => anyhow::Error::new(err).context(what),
    }
}

/// Draws a picture of `size` pixels in memory with `draw`, then writes it to `path` as
/// a PNG, atomically.
pub fn write_png(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Canvas<'_>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let mut pixels = vec![0; rgb_bytes(size)];
    {
        let canvas = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        draw(&canvas).with_context(|| format!("cannot draw {}", path.display()))?;
        canvas.present().map_err(|e| anyhow!("{e}"))?;
    }
    write_atomically(path, |out| {
        let mut encoder = png::Encoder::new(out, size.0, size.1);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(png_io)?;
        writer.write_image_data(&pixels).map_err(png_io)?;
        writer.finish().map_err(png_io)
    })
}

/// Writes an animated GIF of `frames` pictures of `size` pixels to `path`, atomically:
/// `draw(k, canvas)` draws frame k; frames follow each other every `delay_cs`
/// hundredths of a second, and the animation repeats.
pub fn write_gif(
    path: &Path,
    size: (u32, u32),
    frames: u32,
    delay_cs: u16,
    mut draw: impl FnMut(u32, &Canvas<'_>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let (width, height) = (gif_side(size.0)?, gif_side(size.1)?);
    let mut pixels = vec![0; rgb_bytes(size)];
    write_atomically(path, |out| {
        let mut encoder = gif::Encoder::new(out, width, height, &[]).map_err(gif_io)?;
        encoder.set_repeat(gif::Repeat::Infinite).map_err(gif_io)?;
        for frame in 0..frames {
            {
                let canvas = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
                draw(frame, &canvas)
                    .and_then(|()| canvas.present().map_err(|e| anyhow!("{e}")))
                    .map_err(|e| {
                        std::io::Error::other(format!("cannot draw frame {frame}: {e:#}"))
                    })?;
            }
            // Speed 10 of 1 (best) to 30 (fastest) quantises the colours well enough.
            let mut image = gif::Frame::from_rgb_speed(width, height, &pixels, 10);
            image.delay = delay_cs;
            encoder.write_frame(&image).map_err(gif_io)?;
        }
        Ok(())
    })
}

fn rgb_bytes(size: (u32, u32)) -> usize {
    size.0 as usize * size.1 as usize * 3
}

fn gif_side(pixels: u32) -> anyhow::Result<u16> {
    u16::try_from(pixels).map_err(|_| anyhow!("a GIF is at most 65535 pixels wide, not {pixels}"))
}

/// The encoder's I/O error as it was (a full disk stays one), its other errors as text.
fn png_io(err: png::EncodingError) -> std::io::Error {
    match err {
        png::EncodingError::IoError(err) => err,
        other => std::io::Error::other(other.to_string()),
    }
}

fn gif_io(err: gif::EncodingError) -> std::io::Error {
    match err {
        gif::EncodingError::Io(err) => err,
        other => std::io::Error::other(other.to_string()),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_no_file_and_a_full_disk_is_said_in_words() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.png");
        std::fs::write(&path, "the earlier file").unwrap();
        let full = write_atomically(&path, |out| {
            out.write_all(b"half a picture")?;
            Err(std::io::Error::from(ErrorKind::StorageFull))
        })
        .unwrap_err();
        let message = format!("{full:#}");
        assert!(
            message.contains("out.png") && message.contains("is full"),
            "{message}"
        );
        assert!(
            message.contains(&dir.path().display().to_string()),
            "{message}"
        );
        assert!(
            !message.contains("StorageFull") && !message.contains("Os {"),
            "{message}"
        );
        let other =
            write_atomically(&path, |_| Err(std::io::Error::other("a reason"))).unwrap_err();
        assert!(
            format!("{other:#}").ends_with("out.png: a reason"),
            "{other:#}"
        );
        // The earlier file is untouched and no temporary file is left.
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "the earlier file");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
