//! Small helpers shared by subcommands.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::Result;

use diffsvg::Sizing;
use diffsvg::scene::Fonts;

/// Parses a CSS/SVG color (`white`, `#fa0`, `rgb(…)`, `none`) into straight RGBA in
/// `[0, 1]`; a clap value parser.
pub fn parse_color(s: &str) -> std::result::Result<[f32; 4], String> {
    if s.eq_ignore_ascii_case("none") || s.eq_ignore_ascii_case("transparent") {
        return Ok([0.0; 4]);
    }
    let c = svgtypes::Color::from_str(s)
        .map_err(|_| "not a color (a CSS color such as white, #fa0 or rgb(…), or none)")?;
    Ok([
        c.red as f32 / 255.0,
        c.green as f32 / 255.0,
        c.blue as f32 / 255.0,
        c.alpha as f32 / 255.0,
    ])
}

/// `--width` / `--scale`, shared by every command that renders an SVG.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct SizeArgs {
    /// Output width in pixels (height follows the aspect ratio).
    #[arg(long, conflicts_with = "scale")]
    pub width: Option<u32>,
    /// Scale factor applied to the SVG's own size.
    #[arg(long)]
    pub scale: Option<f64>,
}

impl SizeArgs {
    /// The sizing these flags ask for (the library reads them; errors name the flag).
    pub fn sizing(&self) -> Result<Sizing> {
        Sizing::from_options(self.width, None, self.scale).map_err(flag_error)
    }
}

/// `--font`, `--font-dir`, `--font-fallback`: the fonts of `<text>`, shared by every
/// command that reads SVG (and by batch job files, as `font`, `font_dir`, `font_fallback`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct FontArgs {
    /// Font file (TrueType, OpenType, a collection) for `<text>`; repeatable. DejaVu Sans
    /// (the default and sans-serif family), DejaVu Serif and DejaVu Sans Mono are bundled.
    #[arg(long = "font", value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// Folder of font files for `<text>`, searched recursively; repeatable.
    #[arg(long = "font-dir", value_name = "DIR")]
    pub dirs: Vec<PathBuf>,
    /// Set text whose font families are all missing in DejaVu Sans instead of refusing
    /// the file.
    #[arg(long)]
    pub font_fallback: bool,
}

impl FontArgs {
    /// The library's font options for these flags.
    pub fn fonts(&self) -> Fonts {
        self.add_to(Fonts::new())
    }

    /// `base` with these flags' files and folders added, and fallback if asked for.
    pub fn add_to(&self, base: Fonts) -> Fonts {
        let mut f = base;
        if self.font_fallback {
            f = f.with_fallback(true);
        }
        for file in &self.files {
            f = f.with_file(file);
        }
        for dir in &self.dirs {
            f = f.with_dir(dir);
        }
        f
    }
}

/// `out.png` → `out.<suffix>.png`, beside it.
pub fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!("{stem}.{suffix}.png"))
}

/// A library error for the command line: an option out of range
/// ([`diffsvg::Error::Setting`]) is named by its flag (`max_gaussians` →
/// `--max-gaussians`); other errors pass unchanged.
pub fn flag_error(e: diffsvg::Error) -> anyhow::Error {
    match e {
        diffsvg::Error::Setting { name, message } => {
            anyhow::anyhow!("--{} {message}", name.replace('_', "-"))
        }
        e => e.into(),
    }
}

/// Reads a whole file of at most [`MAX_FILE_BYTES`](diffsvg::limits::MAX_FILE_BYTES) bytes,
/// naming it in the error.
pub fn read(path: &Path) -> Result<Vec<u8>> {
    Ok(diffsvg::image_io::read_bounded(
        path,
        diffsvg::limits::MAX_FILE_BYTES,
    )?)
}

/// The library's [`check_output`](diffsvg::image_io::check_output): the extension, not a
/// folder, the folder created and writable.
pub fn check_output(path: &Path, ext: &str) -> Result<()> {
    Ok(diffsvg::image_io::check_output(path, ext)?)
}

/// Prints the library's warnings (one line each, already naming their file) to stderr.
pub fn print_warnings(warnings: &[String]) {
    for w in warnings.iter().take(MAX_WARNINGS) {
        eprintln!("warning: {w}");
    }
    if warnings.len() > MAX_WARNINGS {
        eprintln!(
            "warning: … and {} more warnings like these",
            warnings.len() - MAX_WARNINGS
        );
    }
}

/// Warnings printed at most, the rest counted: a file of 20,000 copies of one dashed
/// path printed 20,000 lines before its error.
const MAX_WARNINGS: usize = 20;

/// Prints the renderer's warnings about `scene` (read from `path`) to stderr, one line
/// each (at most [`MAX_WARNINGS`]): strokes drawn other than the file says because a limit
/// was reached.
pub fn warn_about(scene: &diffsvg::Scene, path: &Path, opts: &diffsvg::raster::RenderOptions) {
    let lines: Vec<String> = diffsvg::raster::warnings(scene, opts)
        .into_iter()
        .map(|w| format!("{}: {w}", path.display()))
        .collect();
    print_warnings(&lines);
}
