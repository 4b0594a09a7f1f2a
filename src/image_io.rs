//! Images in memory and on disk.
//!
//! In memory an [`Image`] holds **premultiplied** RGBA `f32` in `[0, 1]`, sRGB values (no
//! linearization, as browsers and resvg composite), row-major, y down. Files hold straight
//! (not premultiplied) 8-bit RGBA or RGB: PNG and JPEG are read, PNG is written.

use std::io::Write as _;
use std::path::Path;

use crate::error::{Error, Result};

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
            let a = p[3].clamp(0.0, 1.0);
            let un = |c: f32| {
                if a > 0.0 {
                    (c / a).clamp(0.0, 1.0)
                } else {
                    0.0
                }
            };
            out.extend_from_slice(&[to_u8(un(p[0])), to_u8(un(p[1])), to_u8(un(p[2])), to_u8(a)]);
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
        let b = [bg[0] * bg[3], bg[1] * bg[3], bg[2] * bg[3], bg[3]];
        for p in &mut self.data {
            let t = 1.0 - p[3];
            for c in 0..4 {
                p[c] += t * b[c];
            }
        }
    }

    /// Backward of [`over_background`](Self::over_background): turns `∂L/∂(composited)`
    /// (this image) into `∂L/∂(image before compositing)`, in place.
    pub fn over_background_backward(&mut self, bg: [f32; 4]) {
        let b = [bg[0] * bg[3], bg[1] * bg[3], bg[2] * bg[3], bg[3]];
        for g in &mut self.data {
            // out_c = p_c + (1 − p_a)·b_c
            let gb: f32 = (0..4).map(|c| g[c] * b[c]).sum();
            g[3] -= gb;
        }
    }

    /// Reads a PNG or JPEG file (straight alpha in the file), premultiplying.
    pub fn load(path: impl AsRef<Path>) -> Result<Image> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let img = image::load_from_memory(&bytes).map_err(|e| Error::Image {
            path: path.to_path_buf(),
            message: format!("not a readable PNG or JPEG image: {e}"),
        })?;
        let rgba = img.to_rgba8();
        Ok(Image::from_rgba8(
            rgba.width(),
            rgba.height(),
            rgba.as_raw(),
        ))
    }

    /// Writes a PNG (straight alpha) atomically: a temporary file beside the target, then
    /// a rename, so that no half-written file is ever left under the final name.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let mut buf = Vec::new();
        let enc = image::codecs::png::PngEncoder::new(&mut buf);
        image::ImageEncoder::write_image(
            enc,
            &self.to_rgba8(),
            self.width,
            self.height,
            image::ExtendedColorType::Rgba8,
        )
        .map_err(|e| Error::Image {
            path: path.to_path_buf(),
            message: format!("cannot encode PNG: {e}"),
        })?;
        write_atomic(path, &buf)
    }

    /// Resamples to `width × height` with a triangle filter (premultiplied, so edges do
    /// not pick up the color of transparent pixels).
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

/// `[0, 1]` → `0..=255`, rounded.
#[inline]
pub fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
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

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
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
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contact_sheet_places_pairs_in_a_grid() {
        let white = Image::from_rgba8(1, 1, &[255, 255, 255, 255]);
        let red = Image::from_rgba8(1, 1, &[255, 0, 0, 255]);
        let pairs = [(&white, &red), (&white, &red), (&white, &red)];
        let sheet = contact_sheet(&pairs, 2, 1, [0.0, 0.0, 0.0, 1.0]);
        // 2 columns × 2 rows of 1×2 cells with 1 px gaps.
        assert_eq!((sheet.width, sheet.height), (5, 9));
        assert_eq!(sheet.data[(1 * 5 + 1) as usize], [1.0; 4]);
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
}
