//! Every limit that input can reach, in one place.
//!
//! diffsvg sizes its memory and time by the work asked for, never by what a file makes it
//! allocate: each count or size below is checked **before** the allocation it bounds.
//! Past a limit the input is refused with an error naming the file and the limit, except
//! where a fallback is documented (dashes). `docs/limits.md` lists them with what each
//! costs; a test beside each check feeds it the case that used to break.
//!
//! ```
//! use diffsvg::{Scene, Sizing, limits};
//! let huge = format!(
//!     r#"<svg xmlns="http://www.w3.org/2000/svg" width="{0}" height="{0}"/>"#,
//!     limits::MAX_SIDE + 1
//! );
//! let err = Scene::from_svg_str(&huge, "huge.svg", Sizing::Natural).unwrap_err();
//! assert!(err.to_string().starts_with("huge.svg"));
//! ```

/// Largest canvas side, in pixels (rendered scenes and targets).
pub const MAX_SIDE: u32 = 16384;

/// Largest canvas area, in pixels: a rendered `f32` RGBA canvas takes 16 bytes a pixel,
/// so this caps one canvas at 512 MiB (8192 × 4096, or about 5792²).
pub const MAX_PIXELS: u64 = 1 << 25;

/// Largest image read from disk (target photos, dataset photos), in pixels, read from
/// the file's header before anything is decoded.
pub const MAX_IMAGE_PIXELS: u64 = MAX_PIXELS;

/// Most pixels of the raster images of one SVG (`<image>` elements, each PNG, JPEG, GIF or
/// WebP), all together: each image's size is read from its header and counted before it
/// is decoded, and an image that would pass the total is refused with the drawing. A
/// loaded image holds 4 bytes a pixel, and rendering keeps a premultiplied copy of as many.
pub const MAX_SCENE_IMAGE_PIXELS: u64 = MAX_PIXELS;

/// Largest input file read whole (SVG, job file, camera file), in bytes.
pub const MAX_FILE_BYTES: u64 = 64 << 20;

/// Largest font file loaded for `<text>` (`--font`, a file in a `--font-dir`), in bytes,
/// from its size before it is read.
pub const MAX_FONT_BYTES: u64 = 64 << 20;

/// Most font files loaded from `--font` and `--font-dir` together.
pub const MAX_FONT_FILES: usize = 10_000;

/// Deepest folder level searched below a `--font-dir` (a symlink loop ends here).
pub const MAX_FONT_DIR_DEPTH: usize = 16;

/// Largest model file read (a voxel grid), in bytes; its header's counts are checked
/// against its length before anything else is allocated.
pub const MAX_MODEL_BYTES: u64 = 4 << 30;

/// Most Gaussians in a Gaussian-splatting PLY file, and most points in a point-cloud PLY
/// file that initializes them, checked from the header's vertex count before anything is
/// allocated.
pub const MAX_GAUSSIANS: usize = 10_000_000;

/// Largest header of a PLY file, in bytes (its `end_header` line must end within it).
pub const MAX_PLY_HEADER_BYTES: usize = 64 << 10;

/// Largest Gaussian-splatting PLY file read, in bytes: [`MAX_GAUSSIANS`] records of the
/// 62 floats of SH degree 3 (248 bytes each, 2.48 GB in all) plus the largest header.
pub const MAX_SPLAT_BYTES: u64 = MAX_GAUSSIANS as u64 * 248 + MAX_PLY_HEADER_BYTES as u64;

/// Most (tile, Gaussian) pairs of one splatting render: each Gaussian counts the
/// 16 × 16 pixel tiles its 3σ screen box overlaps, and the sum is taken before the
/// per-tile lists (4 bytes a pair) are allocated; past it the render is refused.
/// 2²⁷ pairs take 512 MiB (a million splats covering 128 tiles each).
pub const MAX_SPLAT_TILE_PAIRS: u64 = 1 << 27;

/// Largest decompressed size of a gzip stream (`.svgz`, `.gz` IDX files), in bytes.
pub const MAX_DECOMPRESSED_BYTES: u64 = 256 << 20;

/// Most dashes cut from one path's stroke. Only the part of the centerline near the
/// canvas is cut (chords are clipped to the canvas grown by the stroke's reach; the pattern
/// is advanced over the rest in closed form), and the count is an upper bound taken before
/// cutting: per run of visible chords, `(length / period + 1)` times the pattern's dash
/// entries, a dash with round or square caps counting `1 + cap vertices / 2`. Past it the
/// pattern is dropped and the stroke drawn **solid** (Skia's choice; resvg drops the
/// stroke), in the forward and backward passes alike; `raster::warnings` reports it.
pub const MAX_DASHES_PER_PATH: usize = 100_000;

/// Most dashes cut from all the paths of one drawing, granted path by path in paint order
/// (each also within [`MAX_DASHES_PER_PATH`]): a pattern's tiles, or a style that dashes
/// every element, would otherwise multiply the per-path limit. A dashed stroke past it is
/// drawn **solid**, as past the per-path limit, and `raster::warnings` names it.
pub const MAX_DASHES_PER_SCENE: usize = 1_000_000;

/// Most values in one feConvolveMatrix kernel (`order` columns × rows): a convolution
/// costs that many multiply-adds per pixel of the filter region; a larger kernel is
/// refused when the SVG is read, naming the file.
pub const MAX_CONVOLVE_TAPS: usize = 4096;

/// Most filter primitives on one group (over all its filters): rendering keeps each
/// primitive's result, a layer-sized image of 16 bytes a pixel, for the backward pass; a
/// group with more is refused when the SVG is read, naming the file.
pub const MAX_FILTER_PRIMITIVES: usize = 256;

/// Largest blur deviation evaluated exactly, device pixels
/// ([`RenderOptions::exact_filters`](crate::raster::RenderOptions::exact_filters)): the
/// exact kernel has `⌈5σ⌉` taps a side, each pixel reads at most the layer's side of
/// them. A larger deviation blurs as this one (and has no gradient).
pub const MAX_EXACT_BLUR_SIGMA: f64 = 1000.0;

/// Most octaves of feTurbulence computed; `numOctaves` above it is cut to it. Octave `k`
/// adds at most `2⁻ᵏ` of the noise's range, so the octaves cut change a channel by less
/// than `2⁻²³` (below `f32` resolution).
pub const MAX_TURBULENCE_OCTAVES: u32 = 24;

/// Most flattened chords in one scene (fills and stroke centerlines together, plus the
/// vertices of round joins and caps), counted at load by `Scene::check_limits` from the
/// control points with the flattener's own formula at the default tolerance, before any
/// flattening. A render needs about 110 bytes a chord, a gradient about 220 (measured:
/// 55,000 stroked cubics, 3.9 million chords, at 128 px: 426 MB to render, 830 MB for
/// the gradient); past the limit the scene is refused.
pub const MAX_SCENE_CHORDS: usize = 4_000_000;

/// Deepest nesting of groups composited as layers (`opacity` < 1), checked at load by
/// `Scene::check_limits`. Layers are sized to their content's box, so depth costs
/// compositing time over that box per level, not canvas-wide.
pub const MAX_GROUP_DEPTH: usize = 256;

/// Most elements markers may be copied into, estimated before parsing as the size of the
/// largest `<marker>` times the numbers in all path data (usvg copies a marker's content
/// at every vertex that uses it). The resvg suite's marker files are below 2,000.
pub const MAX_MARKER_NODES: usize = 100_000;

/// Most pattern tiles one drawing may hold, nested patterns' tiles included: each tile is
/// a copy of the pattern's content (shapes of the scene, with their own parameters). A
/// tile smaller than half a pixel draws nothing, as in resvg.
pub const MAX_PATTERN_TILES: usize = 10_000;

/// Most shapes one drawing's pattern tiles may copy in all (tiles × the shapes of each
/// tile's content, nested patterns included): a pattern of 1,000 shapes over a few
/// hundred tiles ran out of memory before this bound.
pub const MAX_PATTERN_SHAPES: usize = 100_000;

/// Most steps a stylesheet's selectors may take to match, estimated before parsing as
/// `elements × depth^(parts − 1)` for the selector with the most compound parts: usvg
/// matches descendant combinators by backtracking over ancestors. Ordinary drawings are far
/// below it (10,000 elements, depth 20, four parts: 8e7); past it the file is refused.
pub const MAX_SELECTOR_WORK: f64 = 1e9;

/// Most chords one cubic is flattened into (a huge curve gets coarser chords, not more).
pub const MAX_CHORDS: u32 = 4096;

/// Largest replay record the backward pass may need for one row band of 16 rows, bytes,
/// by its upper estimate (every cell of every shape's box in the band, 32 bytes each):
/// checked by `raster::check_backward_memory` before `fit`, `grad` and Python's fits.
/// About 16,000 shapes stacked across a 512-wide band; the 2048-blob painterly workload at
/// 2048² needs under a tenth of it.
pub const MAX_BAND_RECORD_BYTES: usize = 256 << 20;

/// Largest radius of an elliptical arc in path data, in the file's units. usvg converts an
/// arc to about `(radius / 0.1)^(1/6)` cubics and takes them from the front of a list, a
/// cost quadratic in their number: 3,000 cubics here, 150,000 (12 s) at 1e30.
pub const MAX_ARC_RADIUS: f64 = 1e20;

/// Largest coordinate magnitude accepted on input and written on output, in device
/// pixels after sizing (far beyond any drawing, well inside `f32`). The reader and the
/// SVG writer apply the same check, and the optimizer's projection keeps every parameter
/// inside it, so diffsvg never writes a file it would refuse to read.
pub const MAX_COORDINATE: f64 = 1e30;

// ---- options of the jobs ------------------------------------------------------------
//
/// Largest mesh file (OBJ, MTL) read, in bytes, from its size before it is read: the
/// parser's memory grows with the file.
pub const MAX_MESH_FILE_BYTES: u64 = 1 << 30;

/// Most vertices of a mesh, counted in the OBJ (`v` lines) before it is parsed.
pub const MAX_MESH_VERTICES: usize = 20_000_000;

/// Most triangles of a mesh, counted in the OBJ (each `f` line's polygon fanned) before it
/// is parsed.
pub const MAX_MESH_TRIANGLES: usize = 20_000_000;

// One bound per option, shared by the command line, batch files and Python (each front
// end names the option its own way: `--max-segments`, `max_segments`). Where the front
// ends once disagreed, the note says which bound was kept and why.

/// Most optimizer steps (or iterations) a job may ask for: 10⁷ steps of even a 28 × 28
/// digit take most of an hour, of a painting days; a count beyond it is a typo, not a
/// request (the fuzzer's `99999999` and `4294967296` ran until killed).
pub const MAX_ITERS: usize = 10_000_000;

/// Most paths a vectorization may use (its budget, `--paths`/`--max-paths`/`paths`):
/// memory and time grow with it. Kept from Python's bound; the command line had none.
pub const MAX_PATHS: usize = 100_000;

/// Most levels of the loss's image pyramid (each halves the picture: 16 levels reach one
/// pixel from the largest canvas). Kept from Python's `1..=16`; the command line had no
/// upper bound.
pub const MAX_PYRAMID_LEVELS: usize = 16;

/// Fewest and most cubic segments of each closed path that adaptive vectorization adds.
/// The command line's `2..=64` is kept: one segment closes on itself as a teardrop with
/// a corner, not a blob (Python accepted 1).
pub const PATH_SEGMENTS: std::ops::RangeInclusive<usize> = 2..=64;

/// Largest magnification of a digit for fitting (`--scale`/`scale`): a 28 × 28 digit
/// becomes 448 × 448. The command line's 16 is kept (Python stopped at 8).
pub const MAX_DIGIT_SCALE: u32 = 16;

/// Most strokes, and most cubic segments per stroke, of a fitted digit.
pub const MAX_DIGIT_CURVES: usize = 16;

/// Most cubic segments of a fitted glyph outline: Python's 1024 is kept (the command
/// line had no upper bound; the fit grows segment by segment, each round a refinement).
pub const MAX_GLYPH_SEGMENTS: usize = 1024;

/// Most rays per iteration of `recon ngp` (each chunk of a batch keeps its samples'
/// gradients until the reduction: about 140 bytes per sample).
pub const MAX_NGP_BATCH: usize = 1 << 20;

/// Refuses `value` outside `range` as an [`Error::Setting`](crate::Error::Setting) naming
/// the option as the library names it (`max_segments`).
pub(crate) fn check_count(
    name: &str,
    value: usize,
    range: std::ops::RangeInclusive<usize>,
) -> crate::Result<()> {
    if range.contains(&value) {
        return Ok(());
    }
    let message = if *range.end() == usize::MAX {
        format!("{value} must be at least {}", range.start())
    } else {
        format!(
            "{value} must be between {} and {}",
            range.start(),
            range.end()
        )
    };
    Err(crate::Error::Setting {
        name: name.into(),
        message,
    })
}
