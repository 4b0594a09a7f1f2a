//! Fonts for SVG `<text>`: which font files usvg lays text out with.
//!
//! usvg turns each `<text>` into glyph outlines (ordinary paths) at parse time, choosing
//! faces from a font database. [`Fonts`] says what goes into that database:
//!
//! * **bundled**, always: DejaVu Sans (regular, bold, oblique, bold oblique), DejaVu Serif
//!   and DejaVu Sans Mono, from the `dejavu` crate, so that text renders the same on a
//!   machine without fonts. DejaVu Sans is the default family (text without
//!   `font-family`) and `sans-serif`; DejaVu Serif is `serif`; DejaVu Sans Mono is
//!   `monospace`.
//! * font **files** and every font of **folders** (searched recursively, `.ttf`, `.otf`,
//!   `.ttc`, `.otc`), each file at most [`MAX_FONT_BYTES`];
//! * the **system's** fonts, when asked for (off by default: the output then depends on
//!   the machine).
//!
//! A `font-family` list none of whose families is loaded is an error naming the file and
//! the families ([`Error::Unsupported`]), unless **fallback** is allowed: then such text
//! is set in the default family. Characters missing from the chosen face are taken from
//! any loaded face that has them (usvg's per-character fallback), fallback or not.
//!
//! ```
//! use diffsvg::{Scene, Sizing, scene::Fonts};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="60" height="20">
//!   <text id="t" x="2" y="16" font-size="16">Hi</text></svg>"#;
//! let scene = Scene::from_svg_str_with(svg, "hi.svg", Sizing::Natural, &Fonts::default())?;
//! assert!(scene.path_count() > 0);
//! let missing = svg.replace("<text ", r#"<text font-family="No Such Font" "#);
//! let err = Scene::from_svg_str_with(&missing, "hi.svg", Sizing::Natural, &Fonts::default());
//! assert!(err.unwrap_err().to_string().contains("No Such Font"));
//! let fallback = Fonts::default().with_fallback(true);
//! assert!(Scene::from_svg_str_with(&missing, "hi.svg", Sizing::Natural, &fallback).is_ok());
//! # Ok::<(), diffsvg::Error>(())
//! ```

use std::path::{Path as FsPath, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use usvg::fontdb;

use crate::error::{Error, Result};
pub use crate::limits::MAX_FONT_BYTES;
use crate::limits::{MAX_FONT_DIR_DEPTH, MAX_FONT_FILES};

/// The family of text without `font-family`, and `sans-serif`, when nothing else is set.
pub const DEFAULT_FAMILY: &str = "DejaVu Sans";

/// A generic CSS font family, which [`Fonts::with_generic`] maps to a loaded family.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Generic {
    /// `serif` (bundled: DejaVu Serif).
    Serif,
    /// `sans-serif` (bundled: DejaVu Sans).
    SansSerif,
    /// `cursive` (nothing bundled).
    Cursive,
    /// `fantasy` (nothing bundled).
    Fantasy,
    /// `monospace` (bundled: DejaVu Sans Mono).
    Monospace,
}

/// Which fonts `<text>` is laid out with: a load option of
/// [`Scene::load_with`](crate::Scene::load_with) and
/// [`parse_tree_with`](super::parse_tree_with). See the [module](self) documentation.
///
/// The font database is built once, on first use, and shared by clones: load many files
/// with one `Fonts` value.
#[derive(Clone, Debug)]
pub struct Fonts {
    files: Vec<PathBuf>,
    dirs: Vec<PathBuf>,
    system: bool,
    fallback: bool,
    default_family: String,
    generic: Vec<(Generic, String)>,
    db: OnceLock<Arc<fontdb::Database>>,
}

impl Default for Fonts {
    /// The bundled fonts only, no fallback.
    fn default() -> Self {
        Fonts {
            files: Vec::new(),
            dirs: Vec::new(),
            system: false,
            fallback: false,
            default_family: DEFAULT_FAMILY.to_string(),
            generic: Vec::new(),
            db: OnceLock::new(),
        }
    }
}

impl PartialEq for Fonts {
    /// The same options (the database built from them is not compared).
    fn eq(&self, o: &Self) -> bool {
        (
            &self.files,
            &self.dirs,
            self.system,
            self.fallback,
            &self.default_family,
            &self.generic,
        ) == (
            &o.files,
            &o.dirs,
            o.system,
            o.fallback,
            &o.default_family,
            &o.generic,
        )
    }
}

/// The one `Fonts::default()` of [`Scene::load`](crate::Scene::load) and its siblings,
/// so that its database is built once per process.
pub(crate) fn bundled() -> &'static Fonts {
    static BUNDLED: OnceLock<Fonts> = OnceLock::new();
    BUNDLED.get_or_init(Fonts::default)
}

impl Fonts {
    /// The bundled fonts only (the same as `Fonts::default()`).
    pub fn new() -> Self {
        Fonts::default()
    }

    /// Also loads this font file (TrueType, OpenType or a collection).
    pub fn with_file(mut self, path: impl Into<PathBuf>) -> Self {
        self.files.push(path.into());
        self.db = OnceLock::new();
        self
    }

    /// Also loads every font file under this folder, recursively.
    pub fn with_dir(mut self, path: impl Into<PathBuf>) -> Self {
        self.dirs.push(path.into());
        self.db = OnceLock::new();
        self
    }

    /// Whether the system's fonts are loaded too (fontconfig's folders on Linux).
    pub fn with_system_fonts(mut self, yes: bool) -> Self {
        self.system = yes;
        self.db = OnceLock::new();
        self
    }

    /// Whether text whose families are all missing is set in the default family instead
    /// of being an error.
    pub fn with_fallback(mut self, yes: bool) -> Self {
        self.fallback = yes;
        self
    }

    /// The family of text without `font-family`, and of fallback.
    pub fn with_default_family(mut self, family: impl Into<String>) -> Self {
        self.default_family = family.into();
        self
    }

    /// Maps a generic family (`serif`, `cursive`, …) to a loaded family.
    pub fn with_generic(mut self, generic: Generic, family: impl Into<String>) -> Self {
        self.generic.retain(|(g, _)| *g != generic);
        self.generic.push((generic, family.into()));
        self.db = OnceLock::new();
        self
    }

    /// The setup of resvg's test harness (`crates/resvg/tests/integration/main.rs`): the
    /// fonts of its `tests/fonts` folder `dir`, serif Noto Serif, sans-serif Noto Sans,
    /// cursive Yellowtail, fantasy Sedgwick Ave Display, monospace Noto Mono, and missing
    /// families set in the serif family, as usvg's own font selector does.
    pub fn resvg_test_suite(dir: impl Into<PathBuf>) -> Self {
        Fonts::default()
            .with_dir(dir)
            .with_generic(Generic::Serif, "Noto Serif")
            .with_generic(Generic::SansSerif, "Noto Sans")
            .with_generic(Generic::Cursive, "Yellowtail")
            .with_generic(Generic::Fantasy, "Sedgwick Ave Display")
            .with_generic(Generic::Monospace, "Noto Mono")
            .with_default_family("Noto Serif")
            .with_fallback(true)
    }

    /// The font files given with [`with_file`](Self::with_file).
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// The folders given with [`with_dir`](Self::with_dir).
    pub fn dirs(&self) -> &[PathBuf] {
        &self.dirs
    }

    /// Whether the system's fonts are loaded.
    pub fn system_fonts(&self) -> bool {
        self.system
    }

    /// Whether missing families fall back to the default family.
    pub fn fallback(&self) -> bool {
        self.fallback
    }

    /// The default family.
    pub fn default_family(&self) -> &str {
        &self.default_family
    }

    /// The font database: the bundled fonts, then the files, folders and system fonts
    /// asked for. Built on the first call and kept. Errors name the font file or folder:
    /// one that cannot be read, a file past [`MAX_FONT_BYTES`], a file given by name that
    /// holds no font, more than [`MAX_FONT_FILES`] files in all.
    pub fn database(&self) -> Result<Arc<fontdb::Database>> {
        if let Some(db) = self.db.get() {
            return Ok(db.clone());
        }
        let db = Arc::new(self.build()?);
        Ok(self.db.get_or_init(|| db).clone())
    }

    fn build(&self) -> Result<fontdb::Database> {
        let mut db = fontdb::Database::new();
        for data in [
            dejavu::sans::regular(),
            dejavu::sans::bold(),
            dejavu::sans::oblique(),
            dejavu::sans::bold_oblique(),
            dejavu::serif::regular(),
            dejavu::sans_mono::regular(),
        ] {
            db.load_font_source(fontdb::Source::Binary(Arc::new(data)));
        }
        db.set_serif_family("DejaVu Serif");
        db.set_sans_serif_family(DEFAULT_FAMILY);
        db.set_monospace_family("DejaVu Sans Mono");
        let mut count = 0usize;
        for f in &self.files {
            if !load_file(&mut db, f, &mut count)? {
                return Err(Error::InvalidValue {
                    path: f.clone(),
                    what: "not a font file (TrueType, OpenType or a collection of them)".into(),
                });
            }
        }
        let mut seen = std::collections::HashSet::new();
        for d in &self.dirs {
            load_dir(&mut db, d, 0, &mut count, &mut seen)?;
        }
        if self.system {
            db.load_system_fonts();
        }
        for (g, family) in &self.generic {
            match g {
                Generic::Serif => db.set_serif_family(family.as_str()),
                Generic::SansSerif => db.set_sans_serif_family(family.as_str()),
                Generic::Cursive => db.set_cursive_family(family.as_str()),
                Generic::Fantasy => db.set_fantasy_family(family.as_str()),
                Generic::Monospace => db.set_monospace_family(family.as_str()),
            }
        }
        Ok(db)
    }

    /// usvg's options for these fonts, and where its font selector records the families
    /// it could not find (read by [`Fonts::check_missing`]).
    pub(crate) fn usvg_options(&self) -> Result<(usvg::Options<'static>, Missing)> {
        let missing: Missing = Arc::default();
        let record = missing.clone();
        let fallback = self.fallback.then(|| self.default_family.clone());
        let select_font: usvg::FontSelectionFn<'static> = Box::new(move |font, db| {
            let families: Vec<fontdb::Family> = font.families().iter().map(family).collect();
            let query = |families: &[fontdb::Family]| {
                db.query(&fontdb::Query {
                    families,
                    weight: fontdb::Weight(font.weight()),
                    stretch: stretch(font.stretch()),
                    style: match font.style() {
                        usvg::FontStyle::Normal => fontdb::Style::Normal,
                        usvg::FontStyle::Italic => fontdb::Style::Italic,
                        usvg::FontStyle::Oblique => fontdb::Style::Oblique,
                    },
                })
            };
            if let Some(id) = query(&families) {
                return Some(id);
            }
            if let Some(default) = &fallback
                && let Some(id) = query(&[fontdb::Family::Name(default)])
            {
                return Some(id);
            }
            let names: Vec<String> = font.families().iter().map(|f| f.to_string()).collect();
            if let Ok(mut m) = record.lock()
                && m.is_none()
            {
                *m = Some(names.join(", "));
            }
            None
        });
        let opt = usvg::Options {
            fontdb: self.database()?,
            font_family: self.default_family.clone(),
            font_resolver: usvg::FontResolver {
                select_font,
                select_fallback: usvg::FontResolver::default_fallback_selector(),
            },
            ..usvg::Options::default()
        };
        Ok((opt, missing))
    }

    /// The error for the first `font-family` list usvg's font selector found no face for.
    pub(crate) fn check_missing(&self, missing: &Missing, name: &FsPath) -> Result<()> {
        let families = missing.lock().ok().and_then(|m| m.clone());
        match families {
            None => Ok(()),
            Some(families) => Err(Error::Unsupported {
                path: name.to_path_buf(),
                what: format!(
                    "font-family {families} of a <text> element: no loaded font has any of \
                     these families (load a font file or folder that does, or allow \
                     fallback to {})",
                    self.default_family
                ),
            }),
        }
    }
}

/// The first family list no font was found for, if any.
pub(crate) type Missing = Arc<Mutex<Option<String>>>;

fn family(f: &svgtypes::FontFamily) -> fontdb::Family<'_> {
    use svgtypes::FontFamily as F;
    match f {
        F::Serif => fontdb::Family::Serif,
        F::SansSerif => fontdb::Family::SansSerif,
        F::Cursive => fontdb::Family::Cursive,
        F::Fantasy => fontdb::Family::Fantasy,
        F::Monospace => fontdb::Family::Monospace,
        F::Named(s) => fontdb::Family::Name(s),
    }
}

fn stretch(s: usvg::FontStretch) -> fontdb::Stretch {
    use usvg::FontStretch as S;
    match s {
        S::UltraCondensed => fontdb::Stretch::UltraCondensed,
        S::ExtraCondensed => fontdb::Stretch::ExtraCondensed,
        S::Condensed => fontdb::Stretch::Condensed,
        S::SemiCondensed => fontdb::Stretch::SemiCondensed,
        S::Normal => fontdb::Stretch::Normal,
        S::SemiExpanded => fontdb::Stretch::SemiExpanded,
        S::Expanded => fontdb::Stretch::Expanded,
        S::ExtraExpanded => fontdb::Stretch::ExtraExpanded,
        S::UltraExpanded => fontdb::Stretch::UltraExpanded,
    }
}

/// Loads one font file after checking its size; whether it held any face.
fn load_file(db: &mut fontdb::Database, path: &FsPath, count: &mut usize) -> Result<bool> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_dir() {
        return Err(Error::InvalidValue {
            path: path.to_path_buf(),
            what: "is a folder, not a font file".into(),
        });
    }
    if meta.len() > MAX_FONT_BYTES {
        return Err(Error::InvalidValue {
            path: path.to_path_buf(),
            what: format!(
                "font file of {} bytes exceeds the limit of {MAX_FONT_BYTES} bytes",
                meta.len()
            ),
        });
    }
    *count += 1;
    if *count > MAX_FONT_FILES {
        return Err(Error::InvalidValue {
            path: path.to_path_buf(),
            what: format!("more than {MAX_FONT_FILES} font files"),
        });
    }
    let before = db.len();
    db.load_font_file(path).map_err(|e| Error::io(path, e))?;
    Ok(db.len() > before)
}

/// Loads every font file (by extension) under `dir`, to [`MAX_FONT_DIR_DEPTH`] levels,
/// each folder once (`seen`: their canonical paths, so symlinks do not loop). Files that
/// hold no font are skipped, as fontdb's own folder loader does.
fn load_dir(
    db: &mut fontdb::Database,
    dir: &FsPath,
    depth: usize,
    count: &mut usize,
    seen: &mut std::collections::HashSet<PathBuf>,
) -> Result<()> {
    let canonical = std::fs::canonicalize(dir).map_err(|e| Error::io(dir, e))?;
    if !seen.insert(canonical) {
        return Ok(());
    }
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    // Sorted, so that the faces (and which of two same-named ones wins) do not depend on
    // the order the file system lists them in.
    entries.sort();
    for path in entries {
        if path.is_dir() {
            if depth < MAX_FONT_DIR_DEPTH {
                load_dir(db, &path, depth + 1, count, seen)?;
            }
            continue;
        }
        let is_font = path.extension().and_then(|e| e.to_str()).is_some_and(|e| {
            ["ttf", "otf", "ttc", "otc"].contains(&e.to_ascii_lowercase().as_str())
        });
        if is_font {
            load_file(db, &path, count)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bundled_faces_and_generic_families() {
        let db = Fonts::new().database().unwrap();
        assert_eq!(db.len(), 6);
        for (generic, name) in [
            (fontdb::Family::SansSerif, DEFAULT_FAMILY),
            (fontdb::Family::Serif, "DejaVu Serif"),
            (fontdb::Family::Monospace, "DejaVu Sans Mono"),
        ] {
            assert_eq!(db.family_name(&generic), name);
            let id = db
                .query(&fontdb::Query {
                    families: &[generic],
                    ..Default::default()
                })
                .unwrap();
            assert!(db.face(id).unwrap().families.iter().any(|f| f.0 == name));
        }
        // Built once: a clone shares it.
        let f = Fonts::new();
        assert!(Arc::ptr_eq(
            &f.database().unwrap(),
            &f.clone().database().unwrap()
        ));
    }

    #[test]
    fn system_fonts_add_to_the_bundled_ones() {
        // The machine may have no fonts at all; the bundled ones are there either way.
        let f = Fonts::new().with_system_fonts(true);
        assert!(f.system_fonts());
        assert!(f.database().unwrap().len() >= 6);
    }

    #[test]
    fn font_folders_are_searched_once_and_bad_files_named() {
        let dir = std::env::temp_dir().join(format!("diffsvg-fonts-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        std::fs::write(dir.join("sub/mono.ttf"), dejavu::sans_mono::bold()).unwrap();
        // Not a font, though named like one: skipped in a folder, refused by name.
        std::fs::write(dir.join("junk.ttf"), b"not a font").unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(&dir, dir.join("sub/loop")).unwrap();
        let db = Fonts::new().with_dir(&dir).database().unwrap();
        assert_eq!(
            db.len(),
            7,
            "the bold mono face once, the loop not followed"
        );
        let e = Fonts::new()
            .with_file(dir.join("junk.ttf"))
            .database()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("junk.ttf") && e.contains("not a font file"),
            "{e}"
        );
        let e = Fonts::new()
            .with_dir(dir.join("none"))
            .database()
            .unwrap_err()
            .to_string();
        assert!(e.contains("none"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_family_error_names_file_and_families() {
        let svg = br#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20">
            <text x="2" y="15" font-family="'Nope', fantasy">Hi</text></svg>"#;
        let e = crate::scene::parse_tree_with(svg, FsPath::new("n.svg"), &Fonts::new())
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("n.svg: unsupported: ") && e.contains("Nope"),
            "{e}"
        );
        assert!(e.contains("fantasy"), "{e}");
        let fonts = Fonts::new().with_fallback(true);
        assert!(crate::scene::parse_tree_with(svg, FsPath::new("n.svg"), &fonts).is_ok());
    }
}
