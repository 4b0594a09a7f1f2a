//! Images in memory and on disk.
//!
//! In memory an [`Image`] holds **premultiplied** RGBA `f32` in `[0, 1]`, sRGB values (no
//! linearization, as browsers and resvg composite), row-major, y down. Files hold straight
//! (not premultiplied) 8-bit RGBA or RGB: PNG and JPEG are read, PNG is written.
//!
//! ```
//! use diffsvg::Image;
//! let red = Image::filled(4, 3, [0.5, 0.0, 0.0, 0.5]); // 50% red, premultiplied
//! assert_eq!(red.to_rgba8()[..4], [255, 0, 0, 128]);   // straight in files
//! let path = std::env::temp_dir().join("diffsvg-doc-image.png");
//! red.save_png(&path)?;
//! let back = Image::load(&path)?;
//! assert_eq!((back.width, back.height), (4, 3));
//! # Ok::<(), diffsvg::Error>(())
//! ```

use std::io::{Read as _, Write as _};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};
use crate::limits::{MAX_FILE_BYTES, MAX_IMAGE_PIXELS, MAX_SIDE};

/// A premultiplied RGBA image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height` premultiplied RGBA pixels, row-major.
    pub data: Vec<[f32; 4]>,
}

impl Image {
    /// A transparent image.
    pub fn new(width: u32, height: u32) -> Self {
        Image::filled(width, height, [0.0; 4])
    }

    /// An image filled with one premultiplied color.
    pub fn filled(width: u32, height: u32, c: [f32; 4]) -> Self {
        Image {
            width,
            height,
            data: vec![c; width as usize * height as usize],
        }
    }

    /// The pixel at `(x, y)`.
    pub fn get(&self, x: u32, y: u32) -> [f32; 4] {
        self.data[y as usize * self.width as usize + x as usize]
    }

    /// Builds an image from straight 8-bit RGBA bytes.
    pub fn from_rgba8(width: u32, height: u32, bytes: &[u8]) -> Self {
        let data = bytes
            .chunks_exact(4)
            .map(|p| {
                let a = p[3] as f32 / 255.0;
                [
                    p[0] as f32 / 255.0 * a,
                    p[1] as f32 / 255.0 * a,
                    p[2] as f32 / 255.0 * a,
                    a,
                ]
            })
            .collect();
        Image {
            width,
            height,
            data,
        }
    }

    /// Builds an image from premultiplied 8-bit RGBA bytes (tiny-skia's pixmap layout).
    pub fn from_premultiplied_rgba8(width: u32, height: u32, bytes: &[u8]) -> Self {
        let data = bytes
            .chunks_exact(4)
            .map(|p| [0, 1, 2, 3].map(|i| p[i] as f32 / 255.0))
            .collect();
        Image {
            width,
            height,
            data,
        }
    }

    /// Straight 8-bit RGBA bytes (rounded, clamped).
    pub fn to_rgba8(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.data.len() * 4);
        for p in &self.data {
            out.extend_from_slice(&straight_rgba8(*p));
        }
        out
    }

    /// The image rounded to 8-bit premultiplied levels, as an 8-bit renderer stores it.
    pub fn quantized(&self) -> Image {
        let mut out = self.clone();
        for p in &mut out.data {
            for c in p.iter_mut() {
                *c = (*c * 255.0).round().clamp(0.0, 255.0) / 255.0;
            }
        }
        out
    }

    /// Composites the image over an opaque or translucent straight color (in `[0, 1]`).
    pub fn over_background(&mut self, bg: [f32; 4]) {
        let b = premultiplied(bg);
        for p in &mut self.data {
            over_background_px(p, b);
        }
    }

    /// Backward of [`over_background`](Self::over_background): turns `∂L/∂(composited)`
    /// (this image) into `∂L/∂(image before compositing)`, in place.
    pub fn over_background_backward(&mut self, bg: [f32; 4]) {
        let b = premultiplied(bg);
        for g in &mut self.data {
            over_background_backward_px(g, b);
        }
    }

    /// Reads a PNG or JPEG file (straight alpha in the file), premultiplying.
    ///
    /// The file is read with a bound ([`MAX_FILE_BYTES`]) and its dimensions are taken
    /// from its header and checked against [`MAX_SIDE`] and [`MAX_IMAGE_PIXELS`] before
    /// anything is decoded, so a small file claiming a huge picture is refused cheaply.
    pub fn load(path: impl AsRef<Path>) -> Result<Image> {
        let path = path.as_ref();
        let bytes = read_bounded(path, MAX_FILE_BYTES)?;
        let unreadable = |e: &dyn std::fmt::Display| Error::Image {
            path: path.to_path_buf(),
            message: format!("not a readable PNG or JPEG image: {e}"),
        };
        let reader = || {
            image::ImageReader::new(std::io::Cursor::new(&bytes[..]))
                .with_guessed_format()
                .map_err(|e| unreadable(&e))
        };
        let (w, h) = reader()?.into_dimensions().map_err(|e| unreadable(&e))?;
        check_image_size(w, h, path)?;
        let mut r = reader()?;
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_SIDE);
        limits.max_image_height = Some(MAX_SIDE);
        // The decoded picture at 16 bits × 4 channels, with room for the decoder's own use.
        limits.max_alloc = Some(MAX_IMAGE_PIXELS * 8 + (64 << 20));
        r.limits(limits);
        let img = r.decode().map_err(|e| unreadable(&e))?;
        let rgba = img.to_rgba8();
        drop(img);
        Ok(Image::from_rgba8(
            rgba.width(),
            rgba.height(),
            rgba.as_raw(),
        ))
    }

    /// Writes a PNG (straight alpha) atomically: a temporary file beside the target, then
    /// a rename, so that no half-written file is ever left under the final name.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<()> {
        save_png_rgba8(self.width, self.height, &self.to_rgba8(), path.as_ref())
    }

    /// [`resized`](Self::resized) to a size chosen by the user, checked first with
    /// [`check_image_size`]; `what` names the choice in the error (a flag such as
    /// `--width`, or a file).
    pub fn resized_checked(&self, width: u32, height: u32, what: &Path) -> Result<Image> {
        check_image_size(width, height, what)?;
        Ok(self.resized(width, height))
    }

    /// Resamples to `width × height` with a triangle filter (premultiplied, so edges do
    /// not pick up the color of transparent pixels). The size is not checked: for a size
    /// that comes from input use [`resized_checked`](Self::resized_checked).
    pub fn resized(&self, width: u32, height: u32) -> Image {
        let mut buf = image::Rgba32FImage::new(self.width, self.height);
        for (i, px) in buf.pixels_mut().enumerate() {
            px.0 = self.data[i];
        }
        let r = image::imageops::resize(&buf, width, height, image::imageops::FilterType::Triangle);
        Image {
            width,
            height,
            data: r.pixels().map(|p| p.0).collect(),
        }
    }
}

/// A premultiplied pixel as straight 8-bit RGBA (rounded, clamped), as files hold it. A
/// pixel whose alpha rounds to 0 is `[0, 0, 0, 0]`: an invisible pixel keeps no color
/// (and the 8-bit render may leave a coverage of a few `2⁻²⁴` out, see
/// [`render_rgba8`](crate::raster::render_rgba8)).
#[inline]
pub(crate) fn straight_rgba8(p: [f32; 4]) -> [u8; 4] {
    let a = p[3].clamp(0.0, 1.0);
    let alpha = to_u8(a);
    if alpha == 0 {
        return [0; 4];
    }
    let un = |c: f32| (c / a).clamp(0.0, 1.0);
    [to_u8(un(p[0])), to_u8(un(p[1])), to_u8(un(p[2])), alpha]
}

/// `[0, 1]` → `0..=255`, rounded.
#[inline]
pub(crate) fn to_u8(v: f32) -> u8 {
    // `⌊y⌋` for `y = 255·v + 0.5` in `[0.5, 255.5]`, in plain float and integer steps that
    // become vector instructions (a saturating cast to an integer is a scalar sequence per
    // value, 70% of an 8-bit render of a flag). Adding 2²³ rounds `y` to the nearest
    // integer, left in the low bits of the sum; one less where that rounded up. NaN
    // counts as 0.
    const MAGIC: f32 = 8_388_608.0; // 2²³: from here on, f32 steps are whole numbers
    let v = if v >= 0.0 { v.min(1.0) } else { 0.0 };
    let y = v * 255.0 + 0.5;
    let m = y + MAGIC;
    let up = u32::from(m - MAGIC > y);
    (m.to_bits() - up) as u8
}

/// Places images left to right on a transparent canvas (for before/after pictures).
pub fn side_by_side(images: &[&Image]) -> Image {
    let w: u32 = images.iter().map(|i| i.width).sum();
    let h = images.iter().map(|i| i.height).max().unwrap_or(0);
    let mut out = Image::new(w, h);
    let mut x0 = 0usize;
    for img in images {
        for y in 0..img.height as usize {
            let src = &img.data[y * img.width as usize..(y + 1) * img.width as usize];
            out.data[y * w as usize + x0..][..src.len()].copy_from_slice(src);
        }
        x0 += img.width as usize;
    }
    out
}

/// A contact sheet: one column per pair, the first image of each pair above the second,
/// `columns` pairs to a row, `gap` pixels of `background` (straight RGBA) between cells.
/// Each cell is the size of the largest image; smaller ones sit at the cell's top left.
pub fn contact_sheet(
    pairs: &[(&Image, &Image)],
    columns: usize,
    gap: u32,
    background: [f32; 4],
) -> Image {
    let columns = columns.max(1);
    let cw = pairs
        .iter()
        .map(|(a, b)| a.width.max(b.width))
        .max()
        .unwrap_or(0);
    let ch = pairs
        .iter()
        .map(|(a, b)| a.height.max(b.height))
        .max()
        .unwrap_or(0);
    let rows = pairs.len().div_ceil(columns) as u32;
    let cols = columns.min(pairs.len()) as u32;
    let w = cols * (cw + gap) + gap;
    let h = rows * (2 * ch + 2 * gap) + gap;
    let a = background[3];
    let bg = [background[0] * a, background[1] * a, background[2] * a, a];
    let mut out = Image::new(w, h);
    out.data.iter_mut().for_each(|p| *p = bg);
    let mut blit = |img: &Image, x0: u32, y0: u32| {
        for y in 0..img.height {
            let src = &img.data[(y * img.width) as usize..((y + 1) * img.width) as usize];
            let start = ((y0 + y) * w + x0) as usize;
            out.data[start..start + src.len()].copy_from_slice(src);
        }
    };
    for (i, (top, bottom)) in pairs.iter().enumerate() {
        let (c, r) = ((i % columns) as u32, (i / columns) as u32);
        let x0 = gap + c * (cw + gap);
        let y0 = gap + r * (2 * ch + 2 * gap);
        blit(top, x0, y0);
        blit(bottom, x0, y0 + ch + gap);
    }
    out
}

/// Encodes straight 8-bit RGBA pixels (`4 · width · height` bytes) as a PNG.
pub(crate) fn encode_png_rgba8(width: u32, height: u32, rgba: &[u8]) -> Vec<u8> {
    let mut buf = Vec::new();
    let enc = image::codecs::png::PngEncoder::new(&mut buf);
    // Writing to memory fails only for a buffer of the wrong length, which the callers'
    // images cannot have.
    image::ImageEncoder::write_image(enc, rgba, width, height, image::ExtendedColorType::Rgba8)
        .expect("PNG encoding into memory");
    buf
}

/// Writes straight 8-bit RGBA pixels (`width × height × 4` bytes, as
/// [`Image::to_rgba8`] or [`render_rgba8`](crate::raster::render_rgba8) gives them) as a
/// PNG, atomically: a temporary file beside the target, then a rename.
pub fn save_png_rgba8(width: u32, height: u32, rgba: &[u8], path: &Path) -> Result<()> {
    write_atomic(path, &encode_png_rgba8(width, height, rgba))
}

/// Decodes an image embedded in a document (PNG, JPEG, GIF's first frame, WebP) to
/// straight 8-bit RGBA: `(width, height, pixels)`. The size is read from the header and
/// checked (at most [`MAX_SIDE`] a side and `max_pixels` in all) **before** anything is
/// decoded; the error is a sentence without the file's name, for the caller to place.
pub(crate) fn decode_embedded(
    bytes: &[u8],
    max_pixels: u64,
) -> std::result::Result<(u32, u32, Vec<u8>), String> {
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| format!("cannot be read: {e}"))
    };
    let (w, h) = reader()?
        .into_dimensions()
        .map_err(|e| format!("cannot be decoded: {e}"))?;
    let pixels = w as u64 * h as u64;
    if w == 0 || h == 0 {
        return Err(format!("is empty ({w}x{h})"));
    }
    if w > MAX_SIDE || h > MAX_SIDE || pixels > max_pixels {
        return Err(format!(
            "is {w}x{h} pixels, past the limit of {MAX_SIDE} a side and {max_pixels} pixels \
             (limits::MAX_SCENE_IMAGE_PIXELS, for all the images of a drawing)"
        ));
    }
    let mut r = reader()?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_SIDE);
    limits.max_image_height = Some(MAX_SIDE);
    limits.max_alloc = Some(pixels * 8 + (64 << 20));
    r.limits(limits);
    let img = r.decode().map_err(|e| format!("cannot be decoded: {e}"))?;
    let rgba = img.to_rgba8();
    Ok((rgba.width(), rgba.height(), rgba.into_raw()))
}

/// Refuses an image size of zero or above [`MAX_SIDE`] per side or [`MAX_IMAGE_PIXELS`]
/// in all; the error names `path` (a file, or a flag such as `--width`).
pub fn check_image_size(width: u32, height: u32, path: &Path) -> Result<()> {
    let bad = |message: String| {
        Err(Error::Image {
            path: path.to_path_buf(),
            message,
        })
    };
    if width == 0 || height == 0 {
        return bad(format!("image size {width}x{height} is empty"));
    }
    if width > MAX_SIDE || height > MAX_SIDE {
        return bad(format!(
            "image size {width}x{height} exceeds the limit of {MAX_SIDE} pixels per side"
        ));
    }
    let pixels = width as u64 * height as u64;
    if pixels > MAX_IMAGE_PIXELS {
        return bad(format!(
            "image size {width}x{height} ({pixels} pixels) exceeds the limit of \
             {MAX_IMAGE_PIXELS} pixels"
        ));
    }
    Ok(())
}

/// Reads a whole file of at most `limit` bytes; a longer file (or an endless one such as
/// `/dev/zero`) is refused after reading `limit + 1` bytes, with an error naming it.
pub fn read_bounded(path: &Path, limit: u64) -> Result<Vec<u8>> {
    let too_big = || {
        Error::io(
            path,
            std::io::Error::other(format!(
                "file is larger than the limit of {}",
                describe_bytes(limit)
            )),
        )
    };
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let meta = f.metadata().map_err(|e| Error::io(path, e))?;
    if meta.is_dir() {
        return Err(Error::io(
            path,
            std::io::Error::other("is a folder, not a file"),
        ));
    }
    if meta.is_file() && meta.len() > limit {
        return Err(too_big());
    }
    let mut out = Vec::with_capacity(if meta.is_file() {
        meta.len() as usize
    } else {
        0
    });
    f.take(limit + 1)
        .read_to_end(&mut out)
        .map_err(|e| Error::io(path, e))?;
    if out.len() as u64 > limit {
        return Err(too_big());
    }
    Ok(out)
}

/// Whether `bytes` start like a gzip stream.
pub(crate) fn is_gzip(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0x1f, 0x8b])
}

/// Decompresses a gzip stream into at most `limit` bytes; a stream that inflates to more
/// (a "gzip bomb") is refused once `limit + 1` bytes have come out. `path` names the file
/// in errors.
pub(crate) fn gunzip_bounded(bytes: &[u8], limit: u64, path: &Path) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(bytes)
        .take(limit + 1)
        .read_to_end(&mut out)
        .map_err(|e| Error::Image {
            path: path.to_path_buf(),
            message: format!("gzip: {e}"),
        })?;
    if out.len() as u64 > limit {
        return Err(Error::Image {
            path: path.to_path_buf(),
            message: format!(
                "gzip stream decompresses to more than the limit of {}",
                describe_bytes(limit)
            ),
        });
    }
    Ok(out)
}

/// `67108864` → `64 MiB`.
pub(crate) fn describe_bytes(n: u64) -> String {
    if n >= 1 << 20 && n.is_multiple_of(1 << 20) {
        format!("{} MiB", n >> 20)
    } else {
        format!("{n} bytes")
    }
}

/// Distinguishes the temporary files of concurrent writers within one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Checks before a long run that `path` can take its output, so that a run does not fail
/// only at its end: the extension is `ext` (any case), the path is not a folder, and its
/// folder exists (created if missing, as `mkdir -p`) and is writable (probed with an empty
/// file, removed at once). The one output check of every writer of both front ends.
pub fn check_output(path: &Path, ext: &str) -> Result<()> {
    let fail = |message: String| Error::Output {
        path: path.to_path_buf(),
        message,
    };
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case(ext) => {}
        _ => return Err(fail(format!("output must be a .{ext} file"))),
    }
    if path.is_dir() {
        return Err(fail("output is a folder".into()));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir)
        .map_err(|e| fail(format!("cannot create the output folder: {e}")))?;
    let probe = dir.join(format!(".diffsvg-probe-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(|e| fail(format!("output folder is not writable: {e}")))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename.
///
/// The temporary name holds the process id, the writing thread and a process-wide
/// counter, so writers never share one, even when they write the same output at once
/// (the last rename wins; each rename is whole). A path that names a device, pipe or
/// socket (`/dev/null`, a FIFO) is written in place instead.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    // A device, pipe or socket (`-o /dev/null`, a FIFO) is written in place: renaming a
    // temporary file over it would replace the device with a regular file.
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| Error::io(path, e))?;
        return f.write_all(bytes).map_err(|e| Error::io(path, e));
    }
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let thread: String = format!("{:?}", std::thread::current().id())
        .chars()
        .filter(char::is_ascii_digit)
        .collect();
    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(".{name}.{}-{thread}-{n}.tmp", std::process::id()));
    let res = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = res {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// A straight RGBA color, premultiplied.
pub(crate) fn premultiplied(c: [f32; 4]) -> [f32; 4] {
    [c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]]
}

/// One pixel of [`Image::over_background`]: `p` (premultiplied) over `b` (premultiplied).
#[inline]
pub(crate) fn over_background_px(p: &mut [f32; 4], b: [f32; 4]) {
    let t = 1.0 - p[3];
    for c in 0..4 {
        p[c] += t * b[c];
    }
}

/// One pixel of [`Image::over_background_backward`]: `out_c = p_c + (1 − p_a)·b_c`, so
/// only `∂L/∂p_a` changes.
#[inline]
pub(crate) fn over_background_backward_px(g: &mut [f32; 4], b: [f32; 4]) {
    let gb: f32 = (0..4).map(|c| g[c] * b[c]).sum();
    g[3] -= gb;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writing "atomically" to `/dev/null` must leave it a device: a rename over it
    /// replaced the device with a regular file (seen once, as root, with `-o /dev/null`).
    #[cfg(unix)]
    #[test]
    fn to_u8_rounds_half_up_as_the_saturating_cast_did() {
        let reference = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
        // Every 3rd f32 from 0 to just past 1, then the specials and negatives.
        let mut bits = 0u32;
        while bits <= 1.01f32.to_bits() {
            let v = f32::from_bits(bits);
            assert_eq!(to_u8(v), reference(v), "{v:e}");
            bits += 3;
        }
        // The values whose `255·v + 0.5` lands on or next to a whole number.
        for k in 0..=256u32 {
            let v = (k as f32 - 0.5) / 255.0;
            for d in -4i32..=4 {
                let w = f32::from_bits((v.to_bits() as i32 + d).max(0) as u32);
                assert_eq!(to_u8(w), reference(w), "{w:e}");
            }
        }
        for v in [
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            -1e-30,
            -5.0,
            7.0,
        ] {
            assert_eq!(to_u8(v), if v.is_nan() { 0 } else { reference(v) }, "{v}");
        }
    }

    #[test]
    fn writing_to_a_device_keeps_the_device() {
        use std::os::unix::fs::FileTypeExt;
        let null = Path::new("/dev/null");
        let is_device = || std::fs::metadata(null).is_ok_and(|m| m.file_type().is_char_device());
        if !is_device() {
            println!("skipped: /dev/null is not a character device here");
            return;
        }
        write_atomic(null, b"discarded").unwrap();
        assert!(is_device(), "/dev/null was replaced");
    }

    #[test]
    fn contact_sheet_places_pairs_in_a_grid() {
        let white = Image::from_rgba8(1, 1, &[255, 255, 255, 255]);
        let red = Image::from_rgba8(1, 1, &[255, 0, 0, 255]);
        let pairs = [(&white, &red), (&white, &red), (&white, &red)];
        let sheet = contact_sheet(&pairs, 2, 1, [0.0, 0.0, 0.0, 1.0]);
        // 2 columns × 2 rows of 1×2 cells with 1 px gaps.
        assert_eq!((sheet.width, sheet.height), (5, 9));
        assert_eq!(sheet.data[(5 + 1) as usize], [1.0; 4]);
        assert_eq!(sheet.data[(3 * 5 + 3) as usize], [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(sheet.data[(5 * 5 + 1) as usize], [1.0; 4]);
        assert_eq!(sheet.data[(5 * 5 + 3) as usize], [0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn rgba8_round_trip_premultiplies() {
        let bytes = [255, 0, 0, 128, 10, 20, 30, 255, 0, 0, 0, 0];
        let img = Image::from_rgba8(3, 1, &bytes);
        assert!((img.data[0][0] - 128.0 / 255.0).abs() < 1e-6);
        assert_eq!(img.to_rgba8(), bytes.to_vec());
    }

    #[test]
    fn atomic_write_leaves_no_temp_and_reports_bad_dirs() {
        let dir = std::env::temp_dir().join(format!("diffsvg-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("a.png");
        Image::filled(2, 2, [0.5, 0.0, 0.0, 0.5])
            .save_png(&f)
            .unwrap();
        let back = Image::load(&f).unwrap();
        assert_eq!((back.width, back.height), (2, 2));
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        // Missing folders are created; a folder that cannot exist (under a file) is an
        // error naming the path.
        let bad = f.join("x.png");
        let e = Image::new(1, 1).save_png(&bad).unwrap_err().to_string();
        assert!(e.contains("a.png"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `digits --indices 0,0` had two threads write one output through one temporary
    /// name: one rename failed and a temporary file was left. Names are now per writer.
    #[test]
    fn parallel_writers_of_one_output_all_succeed() {
        let dir = std::env::temp_dir().join(format!("diffsvg-par-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("same.svg");
        let body = vec![b'x'; 1 << 16];
        std::thread::scope(|s| {
            let handles: Vec<_> = (0..8)
                .map(|_| s.spawn(|| (0..20).map(|_| write_atomic(&f, &body)).collect::<Vec<_>>()))
                .collect();
            for h in handles {
                for r in h.join().unwrap() {
                    r.unwrap();
                }
            }
        });
        assert_eq!(std::fs::read(&f).unwrap(), body);
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            1,
            "no temporary file left"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn reads_are_bounded() {
        let dir = std::env::temp_dir().join(format!("diffsvg-bound-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("ten");
        std::fs::write(&f, [7u8; 10]).unwrap();
        assert_eq!(read_bounded(&f, 10).unwrap().len(), 10);
        let e = read_bounded(&f, 9).unwrap_err().to_string();
        assert!(e.contains("ten") && e.contains("limit of 9 bytes"), "{e}");
        // An endless file stops one byte past the limit.
        let e = read_bounded(Path::new("/dev/zero"), 1 << 20)
            .unwrap_err()
            .to_string();
        assert!(e.contains("/dev/zero") && e.contains("1 MiB"), "{e}");
        assert!(read_bounded(&dir, 10).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
        // A gzip stream is inflated only up to its limit.
        let mut z = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        z.write_all(&[b' '; 5000]).unwrap();
        let gz = z.finish().unwrap();
        assert!(is_gzip(&gz));
        assert_eq!(
            gunzip_bounded(&gz, 5000, Path::new("a.svgz"))
                .unwrap()
                .len(),
            5000
        );
        let e = gunzip_bounded(&gz, 4999, Path::new("a.svgz"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("a.svgz") && e.contains("more than the limit"),
            "{e}"
        );
    }

    #[test]
    fn image_sizes_are_checked() {
        let p = Path::new("t.png");
        assert!(check_image_size(MAX_SIDE, 2, p).is_ok());
        let e = check_image_size(11000, 11000, p).unwrap_err().to_string();
        assert!(e.contains("t.png") && e.contains("11000x11000"), "{e}");
        assert!(check_image_size(MAX_SIDE + 1, 1, p).is_err());
        assert!(check_image_size(0, 5, p).is_err());
        // `vectorize --width 16000` resampled a target to 16000 × 16000 (4 GB) unchecked.
        let e = Image::new(2, 2)
            .resized_checked(16000, 16000, Path::new("--width"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("--width: image size 16000x16000"), "{e}");
        assert_eq!(Image::new(2, 2).resized_checked(3, 1, p).unwrap().width, 3);
    }
}
