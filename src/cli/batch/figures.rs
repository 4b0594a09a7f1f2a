//! A finished job's figures (PSNR, paths) and its thumbnail.

use std::path::Path;

use serde_json::Value;

use super::jobfile::Job;
use diffsvg::image_io::Image;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::Scene;
use diffsvg::scene::Sizing;

/// The thumbnail's file name inside a job folder.
pub const THUMB: &str = "thumb.png";
/// The thumbnail's longest side, in pixels.
const THUMB_SIDE: u32 = 128;

/// What a finished job measured.
#[derive(Debug, Default)]
pub struct Figures {
    /// PSNR in dB, when known.
    pub psnr: Option<f64>,
    /// Paths of the result (render: of the input).
    pub paths: Option<u64>,
    /// Whether `thumb.png` was written.
    pub thumbnail: bool,
}

/// Reads the figures of a job that succeeded (from its `--json` summary line and its
/// outputs) and writes its thumbnail. Missing figures are left out, never an error.
pub fn inspect(job: &Job, dir: &Path, stdout: &str) -> Figures {
    let summary = last_json(stdout);
    let num = |k: &str| {
        summary
            .as_ref()
            .and_then(|v| v.get(k))
            .and_then(Value::as_f64)
    };
    let main = job.output.as_ref().map(|o| dir.join(o));
    match job.kind.as_str() {
        "render" => Figures {
            psnr: compare_psnr(stdout),
            paths: job.inputs.first().and_then(|p| count_paths(p)),
            thumbnail: main.is_some_and(|p| Image::load(p).is_ok_and(|img| save_thumb(dir, &img))),
        },
        "fit" | "vectorize" => {
            let scene = main.and_then(|p| Scene::load(p, Sizing::Natural).ok());
            let paths = num("paths")
                .map(|p| p as u64)
                .or_else(|| scene.as_ref().map(|s| s.path_count() as u64));
            Figures {
                psnr: num("psnr"),
                paths,
                thumbnail: scene.is_some_and(|s| save_thumb(dir, &render_small(s))),
            }
        }
        _ => Figures {
            psnr: num("psnr").or_else(|| num("mean_mse").and_then(mse_psnr)),
            paths: num("paths").map(|p| p as u64),
            thumbnail: Image::load(dir.join("contact.png")).is_ok_and(|img| save_thumb(dir, &img)),
        },
    }
}

/// The last stdout line that is a JSON object with `"done": true`.
fn last_json(stdout: &str) -> Option<Value> {
    stdout
        .lines()
        .rev()
        .filter_map(|l| serde_json::from_str::<Value>(l.trim()).ok())
        .find(|v| v.get("done").and_then(Value::as_bool) == Some(true))
}

/// `render --compare` prints `…, PSNR 43.21 dB; …`.
fn compare_psnr(stdout: &str) -> Option<f64> {
    stdout
        .rsplit("PSNR ")
        .next()
        .filter(|_| stdout.contains("PSNR "))?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// PSNR of images in `[0, 1]` from their mean squared error.
fn mse_psnr(mse: f64) -> Option<f64> {
    (mse > 0.0 && mse.is_finite()).then(|| diffsvg::metrics::psnr_from_mse(mse))
}

fn count_paths(svg: &Path) -> Option<u64> {
    Scene::load(svg, Sizing::Natural)
        .ok()
        .map(|s| s.path_count() as u64)
}

/// Renders a scene at thumbnail size (never larger than its own size).
fn render_small(mut scene: Scene) -> Image {
    let (w, h) = (scene.width, scene.height);
    let side = w.max(h);
    if side > THUMB_SIDE {
        let s = THUMB_SIDE as f64 / side as f64;
        let tw = ((w as f64 * s).round() as u32).max(1);
        let th = ((h as f64 * s).round() as u32).max(1);
        scene.scale_to(s, tw, th);
    }
    render(&scene, &RenderOptions::default())
}

/// Writes `thumb.png`: the image scaled down to at most [`THUMB_SIDE`] on a side.
fn save_thumb(dir: &Path, img: &Image) -> bool {
    let side = img.width.max(img.height);
    if side == 0 {
        return false;
    }
    let small = if side > THUMB_SIDE {
        let s = THUMB_SIDE as f64 / side as f64;
        let tw = ((img.width as f64 * s).round() as u32).max(1);
        let th = ((img.height as f64 * s).round() as u32).max(1);
        img.resized(tw, th)
    } else {
        img.clone()
    };
    small.save_png(dir.join(THUMB)).is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_summary_line_and_the_compare_psnr() {
        let out = "{\"iteration\":0}\n{\"done\":true,\"psnr\":31.5,\"paths\":7}\n";
        let v = last_json(out).unwrap();
        assert_eq!(v["paths"], 7);
        let text = "a.svg: 10x10, vs resvg: MAE 0.1/255, max 3/255, PSNR 48.25 dB; difference";
        assert_eq!(compare_psnr(text), Some(48.25));
        assert_eq!(compare_psnr("nothing"), None);
        assert!((mse_psnr(0.01).unwrap() - 20.0).abs() < 1e-12);
    }
}
