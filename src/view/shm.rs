//! Presenting frames through memory shared with the X server (its MIT-SHM extension):
//! each frame is copied once into a segment the server reads, instead of being sent
//! through the server's socket (2.6 MB a frame at 800 × 800), which the server must then
//! read and copy again. Where the server does not offer it (a remote display, a server
//! without the extension), the window presents as before.

use anyhow::Context;
use x11rb::connection::Connection;
use x11rb::protocol::shm::{self, ConnectionExt as _};
use x11rb::protocol::xproto::{ConnectionExt as _, CreateGCAux, Gcontext, ImageFormat, Window};
use x11rb::rust_connection::RustConnection;

/// A shared segment of one frame's pixels, attached by the X server, and what it takes
/// to copy it into one window.
pub struct SharedFrame {
    connection: RustConnection,
    window: Window,
    gc: Gcontext,
    segment: shm::Seg,
    /// The segment as this process maps it: `len` pixels, 0RGB.
    pixels: *mut u32,
    len: usize,
    width: u16,
    height: u16,
    depth: u8,
}

impl SharedFrame {
    /// A segment for frames of `width` × `height` pixels shown in the X window `window`
    /// of the display in `DISPLAY`; `None` when the server cannot share memory with this
    /// process (the window then presents through the socket).
    pub fn open(window: u32, width: usize, height: usize) -> Option<SharedFrame> {
        let (width, height) = (u16::try_from(width).ok()?, u16::try_from(height).ok()?);
        let (connection, _) = x11rb::connect(None).ok()?;
        connection.shm_query_version().ok()?.reply().ok()?;
        let depth = connection.get_geometry(window).ok()?.reply().ok()?.depth;
        // A depth-24 window takes 32-bit pixels in ZPixmap format, the frame's own
        // 0RGB layout; other depths keep the socket path.
        if depth != 24 {
            return None;
        }
        let len = usize::from(width) * usize::from(height);
        let bytes = len * std::mem::size_of::<u32>();
        // SAFETY: plain System V calls; every result is checked before use, and the
        // segment is marked for removal at once, so it disappears with the last detach
        // (this process's, or its exit, and the server's).
        let (id, pixels) = unsafe {
            let id = libc::shmget(libc::IPC_PRIVATE, bytes, libc::IPC_CREAT | 0o600);
            if id < 0 {
                return None;
            }
            let pixels = libc::shmat(id, std::ptr::null(), 0);
            libc::shmctl(id, libc::IPC_RMID, std::ptr::null_mut());
            if pixels as isize == -1 {
                return None;
            }
            (id, pixels.cast::<u32>())
        };
        let attach = || -> Option<(shm::Seg, Gcontext)> {
            let segment = connection.generate_id().ok()?;
            connection
                .shm_attach(segment, id as u32, true)
                .ok()?
                .check()
                .ok()?;
            let gc = connection.generate_id().ok()?;
            connection
                .create_gc(gc, window, &CreateGCAux::new())
                .ok()?
                .check()
                .ok()?;
            Some((segment, gc))
        };
        match attach() {
            Some((segment, gc)) => Some(SharedFrame {
                connection,
                window,
                gc,
                segment,
                pixels,
                len,
                width,
                height,
                depth,
            }),
            None => {
                // SAFETY: mapped above and not used since.
                unsafe { libc::shmdt(pixels.cast()) };
                None
            }
        }
    }

    /// Shows `frame` (exactly the segment's size) in the window, and returns once the
    /// server has read it, so the next frame may overwrite the segment.
    pub fn present(&mut self, frame: &[u32]) -> anyhow::Result<()> {
        anyhow::ensure!(
            frame.len() == self.len,
            "a frame of {} pixels for a window of {}",
            frame.len(),
            self.len
        );
        // SAFETY: the segment holds `len` pixels and stays mapped while `self` lives;
        // the server reads it only during the request below, which the round trip
        // after it waits for.
        unsafe { std::ptr::copy_nonoverlapping(frame.as_ptr(), self.pixels, self.len) };
        let lost = "lost the X display";
        self.connection
            .shm_put_image(
                self.window,
                self.gc,
                self.width,
                self.height,
                0,
                0,
                self.width,
                self.height,
                0,
                0,
                self.depth,
                ImageFormat::Z_PIXMAP.into(),
                false,
                self.segment,
                0,
            )
            .context(lost)?;
        // A request with a reply: the server handles requests in order, so when the
        // reply comes, the image has been copied out of the segment.
        self.connection
            .get_input_focus()
            .context(lost)?
            .reply()
            .context(lost)?;
        Ok(())
    }
}

impl Drop for SharedFrame {
    fn drop(&mut self) {
        // The server detaches on its own when the connection closes; asking first
        // frees the segment sooner. Errors do not matter on the way out.
        if let Ok(cookie) = self.connection.shm_detach(self.segment) {
            let _ = cookie.check();
        }
        let _ = self.connection.free_gc(self.gc);
        let _ = self.connection.flush();
        // SAFETY: mapped in `open`; nothing reads it after this.
        unsafe { libc::shmdt(self.pixels.cast()) };
    }
}
