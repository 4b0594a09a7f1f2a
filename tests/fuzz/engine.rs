//! The in-tree mutation fuzzer, shared by the bounded CI run (`tests/integration/fuzz.rs`)
//! and the campaign runner (`examples/fuzz.rs`). Stable Rust, no extra dependencies.
//!
//! Each case is drawn from a seed and its number alone (a SplitMix64 stream), so
//! `(seed, case)` reproduces it exactly. A case takes a valid input (an SVG from
//! `svg-samples/` or, when asked, the resvg suite; a job file; an IDX file; a scene folder;
//! a voxel model), mutates it 1 to 4 times (byte flips, inserts, deletes, splices from
//! another input, numbers replaced by extremes, elements duplicated or nested hundreds of
//! levels deep, attributes swapped or hostile ones injected, header fields replaced) and
//! runs the release binary on it as a child process, in a fresh folder, under
//! `ulimit -v` (the memory ceiling: an allocation past it fails, and Rust aborts) with a
//! time limit. The oracle, for every command:
//!
//! * no panic (`panicked at` on stderr), no abort, no signal, no stack overflow;
//! * exit status 0 or 2 (`batch`: 0, 1 or 2, as docs/batch.md says), and status 2 ends
//!   with an `error: …` line;
//! * on a non-zero exit, no file under the case's `out/` folder (nor a temporary file);
//!   on exit 0, the command's main output exists;
//! * peak resident memory (`VmHWM`, polled) under the ceiling, and the run within the
//!   time limit;
//! * `batch`: no job of the summary died of a panic, an abort or a signal.
//!
//! A failure is keyed by command and kind (the panic's source location, the signal, the
//! exit status, …), so that distinct failures can be counted.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The fuzzer's choices, drawn from the library's deterministic generator.
#[derive(Clone, Debug)]
pub struct Rng(diffsvg::scene::random::Rng);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Rng {
        Rng(diffsvg::scene::random::Rng::new(seed))
    }

    /// The next 64 random bits (the library's SplitMix64, so cases stay reproducible).
    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }

    /// A random element.
    pub fn pick<'a, T>(&mut self, v: &'a [T]) -> &'a T {
        &v[self.below(v.len())]
    }
}

/// How a fuzzing run is set up.
#[derive(Clone, Debug)]
pub struct Config {
    /// The `diffsvg` binary (release build).
    pub bin: PathBuf,
    /// Scratch folder for cases (emptied per case).
    pub work: PathBuf,
    /// The campaign's seed; case `i` uses a generator derived from `(seed, i)`.
    pub seed: u64,
    /// Address-space limit of each child, KiB (`ulimit -v`): over-allocation aborts there.
    pub mem_limit_kib: u64,
    /// Largest accepted peak resident memory of a child, KiB.
    pub rss_ceiling_kib: u64,
    /// Time limit of one child.
    pub timeout: Duration,
    /// The crate root (for `svg-samples/`).
    pub root: PathBuf,
    /// Extra SVG seeds (e.g. `../shared/data/resvg-tests`), searched recursively.
    pub extra_svgs: Option<PathBuf>,
    /// Where failing cases are copied (one folder each, with `cmd.sh`), if anywhere.
    pub repro_dir: Option<PathBuf>,
    /// Most reproducers kept per distinct failure.
    pub repro_per_kind: usize,
}

impl Config {
    /// Defaults: 1 GiB of address space and of resident memory, 10 s a case.
    pub fn new(bin: PathBuf, work: PathBuf, root: PathBuf, seed: u64) -> Config {
        Config {
            bin,
            work,
            seed,
            mem_limit_kib: 1 << 20,
            rss_ceiling_kib: 1 << 20,
            timeout: Duration::from_secs(10),
            root,
            extra_svgs: None,
            repro_dir: None,
            repro_per_kind: 3,
        }
    }
}

/// The commands the fuzzer drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Target {
    /// `render IN.svg -o out/r.png --width 128`
    Render,
    /// `fit IN.svg TARGET -o out/f.svg --iters 2`
    Fit,
    /// `vectorize TARGET -o out/v.svg --paths 2 --iters 2`
    Vectorize,
    /// `digits --images IDX [--labels IDX] -o out/d` (small settings)
    Digits,
    /// `batch JOBS.{toml,json} -o out/b`
    Batch,
    /// `recon voxel --scene DIR -o out/m.vox --iters 2 --res 8`
    Recon,
    /// `view MODEL.vox [--scene DIR] -o out/views`
    View,
}

impl Target {
    /// Every target, with its share of the cases (out of 100).
    pub const WEIGHTS: [(Target, usize); 7] = [
        (Target::Render, 34),
        (Target::Fit, 10),
        (Target::Vectorize, 10),
        (Target::Digits, 10),
        (Target::Batch, 8),
        (Target::Recon, 16),
        (Target::View, 12),
    ];

    /// The subcommand's name.
    pub fn name(self) -> &'static str {
        match self {
            Target::Render => "render",
            Target::Fit => "fit",
            Target::Vectorize => "vectorize",
            Target::Digits => "digits",
            Target::Batch => "batch",
            Target::Recon => "recon",
            Target::View => "view",
        }
    }
}

/// One generated case: files to write into the case folder and the arguments (paths
/// relative to that folder, where the child runs).
#[derive(Clone, Debug)]
pub struct Case {
    /// The command driven.
    pub target: Target,
    /// `(relative path, contents)` to write before running.
    pub files: Vec<(String, Vec<u8>)>,
    /// The arguments after the binary.
    pub args: Vec<String>,
    /// The main output, relative to the case folder (must exist after exit 0).
    pub output: String,
    /// What was done to the input, for the report.
    pub mutations: Vec<String>,
}

/// What a child did.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Exit status, when it exited.
    pub code: Option<i32>,
    /// Whether it was killed for running past the time limit.
    pub timed_out: bool,
    /// Its standard error (the first 64 KiB).
    pub stderr: String,
    /// Peak resident memory seen, KiB.
    pub peak_kib: u64,
    /// Wall-clock seconds.
    pub secs: f64,
}

/// A case that broke the oracle.
#[derive(Clone, Debug)]
pub struct Failure {
    /// Case number within the campaign.
    pub case: u64,
    /// `command: kind`, the key of distinct failures.
    pub key: String,
    /// Details: exit status, the end of stderr, memory, time, mutations.
    pub detail: String,
    /// The command line, to run in the reproducer's folder.
    pub command: String,
    /// Where the reproducer was saved, if it was.
    pub saved: Option<PathBuf>,
}

/// The fuzzer: seeds loaded once, cases generated and run one at a time.
pub struct Fuzzer {
    cfg: Config,
    svgs: Vec<(String, Vec<u8>)>,
    /// A valid voxel model (written by the binary at start-up), for `view`.
    model: Vec<u8>,
    /// A decompressed-size bomb for `digits` (a gzip of zeros with a valid header).
    bomb: Vec<u8>,
    /// Reproducers saved so far per key.
    saved: BTreeMap<String, usize>,
    /// Per command: cases run, exits 0, exits 2 (or 1 for batch), failures.
    pub stats: BTreeMap<&'static str, [u64; 4]>,
}

/// Numbers put in place of a number of the input. `3.4e38` and its kin are finite in
/// `f32` (so no NaN/overflow check refuses them) but overflow as soon as two are added.
const EXTREMES: [&str; 25] = [
    "1e-30",
    "1e30",
    "-1e30",
    "1e9",
    "-1e9",
    "-0",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e308",
    "1e-5",
    "1e-4",
    "0",
    "-1",
    "4294967296",
    "18446744073709551616",
    "99999999",
    "1e38",
    "3.4e38",
    "-3.4e38",
    "3.4028234e38",
    "3.4e39",
    "0.000000000000000000000000000000000000000000001",
    "123456789012345678901234567890",
];

/// Extremes that are valid JSON numbers (and TOML numbers).
const JSON_EXTREMES: [&str; 14] = [
    "1e-30",
    "1e30",
    "-1e30",
    "1e9",
    "-1e9",
    "-0",
    "1e308",
    "1e-5",
    "0",
    "-1",
    "4294967296",
    "99999999",
    "1e38",
    "3.4e39",
];

/// Hostile attributes injected into an SVG element.
const ATTRS: [&str; 24] = [
    r#"stroke-dasharray="1e-5" stroke="black""#,
    r#"stroke-dasharray="0.001 1e-30" stroke="black""#,
    r#"stroke-dasharray="1 1" stroke="black" stroke-width="3""#,
    r#"style="stroke-width:1e38;stroke:black""#,
    r#"style="stroke-dasharray:1e-4;stroke:red""#,
    r#"transform="scale(1e30)""#,
    r#"transform="scale(1e-30)""#,
    r#"transform="matrix(0 0 0 0 0 0)""#,
    r#"transform="rotate(1e30) translate(1e9 -1e9)""#,
    r#"stroke-width="1e6" stroke="black""#,
    r#"opacity="NaN""#,
    r#"opacity="0.5""#,
    r#"fill-opacity="-1e30""#,
    r#"x="1e9""#,
    r#"r="1e30""#,
    r#"width="1e9" height="1e9""#,
    r#"viewBox="0 0 1e-30 1e-30""#,
    r#"font-size="1e30""#,
    r#"stroke-miterlimit="1e30" stroke="black" stroke-linejoin="miter""#,
    r#"stroke-linecap="round" stroke="black" stroke-width="1e-30""#,
    r#"fill="url(#nonexistent)""#,
    r#"filter="url(#f)""#,
    r#"mask="url(#m)""#,
    r#"clip-path="url(#c)""#,
];

/// Fragments inserted at random places of an SVG.
const SVG_SNIPPETS: [&str; 20] = [
    "<g>",
    "</g>",
    "<g opacity=\"0.5\">",
    "\"",
    "<",
    ">",
    "&",
    "&#0;",
    "<!--",
    "<![CDATA[",
    "<style>*{stroke-dasharray:1e-4;stroke:black}</style>",
    "<style>path{stroke-width:1e38}</style>",
    "<path d=\"M0 0C1e30 0 0 1e30 9 9\" stroke=\"black\"/>",
    "<line x2=\"1e9\" y2=\"-1e9\" stroke=\"black\" stroke-width=\"1e6\"/>",
    "<circle r=\"1e30\" fill=\"none\" stroke=\"black\" stroke-dasharray=\"5 3\"/>",
    "<linearGradient id=\"g\" x2=\"1e-9\" spreadMethod=\"reflect\"><stop offset=\"0\"/><stop offset=\"1\" stop-color=\"red\"/></linearGradient>",
    "<use href=\"#g\"/>",
    "<text>x</text>",
    "<image href=\"data:image/png;base64,AAAA\"/>",
    "<rect width=\"198\" height=\"198\" fill=\"none\" stroke=\"black\" stroke-dasharray=\"1e-5\"/>",
];

/// Whole elements appended at the end of an SVG, each with `{X}` replaced by an extreme
/// number: the regions usvg computes while parsing (filters, images, masks, clip paths,
/// patterns, markers) and arcs whose endpoint, not their radius, is far (issue 27: a
/// filter or `<image>` 3.4e38 wide panicked inside usvg, `a48 48 0 0 0 7.1 1e38` hung).
pub const REGION_SNIPPETS: [&str; 16] = [
    r#"<filter id="zf" width="{X}"><feGaussianBlur stdDeviation="2"/></filter><rect width="50" height="50" filter="url(#zf)"/>"#,
    r#"<filter id="zf" x="{X}" y="-{X}"><feOffset dx="3"/></filter><rect width="50" height="50" filter="url(#zf)"/>"#,
    r#"<filter id="zf" filterUnits="userSpaceOnUse" width="{X}" height="{X}"><feFlood flood-color="red"/></filter><g filter="url(#zf)"><rect width="50" height="50"/></g>"#,
    r#"<filter id="zf"><feGaussianBlur stdDeviation="{X}"/><feMorphology radius="{X}"/></filter><rect width="50" height="50" filter="url(#zf)"/>"#,
    r#"<filter id="zf" primitiveUnits="objectBoundingBox"><feFlood x="{X}" width="{X}"/></filter><rect width="50" height="50" filter="url(#zf)"/>"#,
    r#"<image width="{X}" height="20" href="data:image/png;base64,iVBORw0KGgo="/>"#,
    r#"<image x="{X}" width="20" height="{X}" href="missing.png"/>"#,
    r#"<mask id="zm" width="{X}" height="{X}"><rect width="50" height="50" fill="white"/></mask><rect width="50" height="50" mask="url(#zm)"/>"#,
    r#"<mask id="zm" maskContentUnits="objectBoundingBox"><rect width="{X}" height="1" fill="white"/></mask><rect width="50" height="50" mask="url(#zm)"/>"#,
    r#"<clipPath id="zc" clipPathUnits="objectBoundingBox"><rect width="{X}" height="{X}"/></clipPath><rect width="50" height="50" clip-path="url(#zc)"/>"#,
    r#"<pattern id="zp" width="{X}" height="{X}" patternUnits="userSpaceOnUse"><rect width="5" height="5"/></pattern><rect width="50" height="50" fill="url(#zp)"/>"#,
    r#"<marker id="zk" markerWidth="{X}" viewBox="0 0 {X} 10"><path d="M0 0H10"/></marker><path d="M10 10H40" stroke="black" marker-end="url(#zk)"/>"#,
    r#"<path d="M10 10 a48 48 0 0 0 7.1 {X}z"/>"#,
    r#"<path d="M10 10 A5 5 0 1 1 {X} -{X}" stroke="black"/>"#,
    r#"<path d="M{X} 10 a1 1 0 0 0 -{X} {X}" fill="red"/>"#,
    r#"<svg width="{X}" height="20" viewBox="0 0 {X} {X}"><rect width="9" height="9"/></svg>"#,
];

/// The first number of the directed cases in reports and reproducer folders.
pub const DIRECTED_BASE: u64 = 1_000_000_000;

/// The extremes [`REGION_SNIPPETS`] are tried with in [`Fuzzer::directed`].
pub const REGION_EXTREMES: [&str; 4] = ["3.4e38", "1e38", "1e30", "1e-30"];

/// Fragments inserted into job files.
const JOB_SNIPPETS: [&str; 14] = [
    "\"",
    "[",
    "]",
    "{",
    "=",
    "\n[[job]]\n",
    "\ninput = \"*\"\n",
    "\ninput = \"**/*.svg\"\n",
    "\nname = \"../x\"\n",
    "\nname = \"日本\"\n",
    "\noutput = \"/proc/x\"\n",
    "\nwidth = 1e30\n",
    "\ncompare = true\n",
    "\0",
];

impl Fuzzer {
    /// Loads the seeds and prepares a valid voxel model with the binary.
    pub fn new(cfg: Config) -> Result<Fuzzer, String> {
        if !cfg.bin.is_file() {
            return Err(format!(
                "{}: no diffsvg binary (cargo build --release)",
                cfg.bin.display()
            ));
        }
        let mut svgs = Vec::new();
        let samples = cfg.root.join("svg-samples");
        collect_svgs(&samples, &samples, &mut svgs);
        if let Some(extra) = &cfg.extra_svgs {
            collect_svgs(extra, extra, &mut svgs);
        }
        if svgs.is_empty() {
            return Err(format!("{}: no SVG seeds", samples.display()));
        }
        std::fs::create_dir_all(&cfg.work).map_err(|e| format!("{}: {e}", cfg.work.display()))?;
        let mut fz = Fuzzer {
            cfg,
            svgs,
            model: Vec::new(),
            bomb: Vec::new(),
            saved: BTreeMap::new(),
            stats: BTreeMap::new(),
        };
        fz.model = fz.make_model()?;
        fz.bomb = gzip(&idx_bomb());
        Ok(fz)
    }

    /// The number of SVG seeds.
    pub fn svg_seeds(&self) -> usize {
        self.svgs.len()
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Trains a tiny model on the seed scene, for `view`.
    fn make_model(&self) -> Result<Vec<u8>, String> {
        let dir = self.cfg.work.join("model");
        let _ = std::fs::remove_dir_all(&dir);
        write_files(&dir, &synthetic_scene(&mut Rng::new(1), "scene"))?;
        let out = Command::new(&self.cfg.bin)
            .args([
                "recon", "voxel", "--scene", "scene", "-o", "m.vox", "--iters", "4", "--res", "8",
                "--batch", "64", "--quiet",
            ])
            .current_dir(&dir)
            .env("RAYON_NUM_THREADS", "2")
            .stdout(Stdio::null())
            .output()
            .map_err(|e| format!("runs {}: {e}", self.cfg.bin.display()))?;
        if !out.status.success() {
            return Err(format!(
                "the seed model could not be trained: {}",
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        std::fs::read(dir.join("m.vox")).map_err(|e| format!("m.vox: {e}"))
    }

    /// Generates case `i` of the campaign (deterministic given the seed).
    pub fn generate(&self, i: u64) -> Case {
        let mut rng = Rng::new(self.cfg.seed ^ i.wrapping_mul(0xd134_2543_de82_ef95));
        rng.next_u64();
        let mut roll = rng.below(100);
        let mut target = Target::Render;
        for (t, w) in Target::WEIGHTS {
            if roll < w {
                target = t;
                break;
            }
            roll -= w;
        }
        match target {
            Target::Render => self.case_render(&mut rng),
            Target::Fit => self.case_fit(&mut rng),
            Target::Vectorize => self.case_vectorize(&mut rng),
            Target::Digits => self.case_digits(&mut rng),
            Target::Batch => self.case_batch(&mut rng),
            Target::Recon => self.case_recon(&mut rng),
            Target::View => self.case_view(&mut rng),
        }
    }

    fn seed_svg(&self, rng: &mut Rng) -> (String, Vec<u8>) {
        self.svgs[rng.below(self.svgs.len())].clone()
    }

    /// A mutated seed SVG and the mutations' description.
    fn mutated_svg(&self, rng: &mut Rng) -> (Vec<u8>, Vec<String>) {
        let (name, mut svg) = self.seed_svg(rng);
        let mut log = vec![format!("seed {name}")];
        for _ in 0..1 + rng.below(4) {
            let donor = self.seed_svg(rng).1;
            log.push(mutate_svg(rng, &mut svg, &donor));
        }
        (svg, log)
    }

    fn case_render(&self, rng: &mut Rng) -> Case {
        let (svg, mutations) = self.mutated_svg(rng);
        let mut args = strings(&["render", "in.svg", "-o", "out/r.png", "--width", "128"]);
        if rng.chance(0.1) {
            args.push("--background".into());
            args.push(rng.pick(&["white", "#0000", "none", "red"]).to_string());
        }
        Case {
            target: Target::Render,
            files: vec![("in.svg".into(), svg)],
            args,
            output: "out/r.png".into(),
            mutations,
        }
    }

    fn case_fit(&self, rng: &mut Rng) -> Case {
        let (svg, mut mutations) = self.mutated_svg(rng);
        // The target: an unmutated seed (same one or another), sometimes a mutated PNG.
        let (tname, target) = self.seed_svg(rng);
        mutations.push(format!("target {tname}"));
        let mut files = vec![("in.svg".to_string(), svg), ("target.svg".into(), target)];
        let mut tpath = "target.svg";
        if rng.chance(0.25) {
            let (w, h) = (16 + rng.below(48) as u32, 16 + rng.below(48) as u32);
            let mut png = tiny_png(rng, w, h);
            mutations.push(mutate_png(rng, &mut png));
            files.push(("target.png".into(), png));
            tpath = "target.png";
        }
        let mut args = strings(&["fit", "in.svg", tpath, "-o", "out/f.svg", "--iters", "2"]);
        if rng.chance(0.2) {
            let flag = rng.pick(&["--lr-points", "--lr-color", "--lr-width", "--lr-opacity"]);
            args.push(flag.to_string());
            args.push(rng.pick(&["1e308", "1e30", "1e9", "0"]).to_string());
            mutations.push(format!("{} {}", args[args.len() - 2], args[args.len() - 1]));
        }
        Case {
            target: Target::Fit,
            files,
            args,
            output: "out/f.svg".into(),
            mutations,
        }
    }

    fn case_vectorize(&self, rng: &mut Rng) -> Case {
        let (file, bytes, mutations) = if rng.chance(0.5) {
            let (svg, m) = self.mutated_svg(rng);
            ("in.svg", svg, m)
        } else {
            // A fifth of the pictures are one to three pixels in one direction or both.
            let side = |rng: &mut Rng| match rng.chance(0.2) {
                true => 1 + rng.below(3) as u32,
                false => 8 + rng.below(64) as u32,
            };
            let (w, h) = (side(rng), side(rng));
            let mut png = tiny_png(rng, w, h);
            let m = if rng.chance(0.7) {
                mutate_png(rng, &mut png)
            } else {
                format!("valid {w}x{h} PNG")
            };
            ("in.png", png, vec![m])
        };
        let mut args = strings(&[
            "vectorize",
            file,
            "-o",
            "out/v.svg",
            "--paths",
            "2",
            "--iters",
            "2",
        ]);
        // SVGs are drawn 64 wide; pictures are taken as they are (tiny ones stay tiny).
        if file == "in.svg" || rng.chance(0.3) {
            args.extend(strings(&["--width", "64"]));
        }
        if rng.chance(0.4) {
            let mode = *rng.pick(&["fixed", "painterly", "adaptive"]);
            args.extend(strings(&["--mode", mode]));
        }
        if rng.chance(0.2) {
            args.extend(strings(&["--pyramid", "3"]));
        }
        Case {
            target: Target::Vectorize,
            files: vec![(file.into(), bytes)],
            args,
            output: "out/v.svg".into(),
            mutations,
        }
    }

    fn case_digits(&self, rng: &mut Rng) -> Case {
        let mut images = idx_images(3);
        let mut labels = idx_labels(3);
        let mut mutations = Vec::new();
        let bomb = rng.chance(0.05);
        if bomb {
            images = self.bomb.clone();
            mutations.push(format!(
                "gzip bomb (valid header, {BOMB_IMAGES} images of zeros)"
            ));
        } else {
            for _ in 0..1 + rng.below(3) {
                if rng.chance(0.8) {
                    mutations.push(format!("images: {}", mutate_idx(rng, &mut images)));
                } else {
                    mutations.push(format!("labels: {}", mutate_idx(rng, &mut labels)));
                }
            }
        }
        let gz = !bomb && rng.chance(0.3);
        let img_name = if bomb || gz { "images.gz" } else { "images" };
        if gz {
            images = gzip(&images);
        }
        let indices = *rng.pick(&[
            "0..2",
            "0..2",
            "0..2",
            "1",
            "0,0",
            "0..3",
            "4294967295",
            "0..100000000",
            "2..1",
        ]);
        mutations.push(format!("--indices {indices}"));
        let mut args = strings(&[
            "digits",
            "--images",
            img_name,
            "--indices",
            indices,
            "-o",
            "out/d",
            "--steps",
            "2",
            "--stage-steps",
            "2",
            "--max-strokes",
            "1",
            "--max-segments",
            "1",
            "--quiet",
        ]);
        let mut files = vec![(img_name.to_string(), images)];
        if rng.chance(0.5) {
            args.push("--labels".into());
            args.push("labels".into());
            files.push(("labels".into(), labels));
        }
        Case {
            target: Target::Digits,
            files,
            args,
            output: "out/d/summary.csv".into(),
            mutations,
        }
    }

    fn case_batch(&self, rng: &mut Rng) -> Case {
        let (_, svg) = self.seed_svg(rng);
        let json = rng.chance(0.4);
        let mut text = if json {
            r#"{"output": "ignored", "job": [
  {"kind": "render", "name": "r", "input": "in/*.svg", "width": 64},
  {"kind": "vectorize", "name": "v", "input": "in/a.svg", "paths": 2, "iters": 2, "width": 48},
  {"kind": "fit", "name": "f", "init": "in/a.svg", "target": "in/a.svg", "iters": 2},
  {"kind": "digits", "name": "d", "images": "images", "indices": "0..2", "steps": 2, "stage_steps": 2, "max_strokes": 1, "max_segments": 1}
]}
"#
            .to_string()
        } else {
            r#"output = "ignored"

[[job]]
kind = "render"
name = "r"
input = "in/*.svg"
width = 64

[[job]]
kind = "vectorize"
name = "v"
input = "in/a.svg"
paths = 2
iters = 2
width = 48

[[job]]
kind = "fit"
name = "f"
init = "in/a.svg"
target = "in/a.svg"
iters = 2

[[job]]
kind = "digits"
name = "d"
images = "images"
indices = "0..2"
steps = 2
stage_steps = 2
max_strokes = 1
max_segments = 1
"#
            .to_string()
        };
        let mut mutations = Vec::new();
        for _ in 0..1 + rng.below(3) {
            let mut bytes = std::mem::take(&mut text).into_bytes();
            let extremes: &[&str] = if json { &JSON_EXTREMES } else { &EXTREMES };
            mutations.push(mutate_text_with(
                rng,
                &mut bytes,
                &[],
                &JOB_SNIPPETS,
                extremes,
                !json,
                2,
            ));
            text = String::from_utf8_lossy(&bytes).into_owned();
        }
        let name = if json { "jobs.json" } else { "jobs.toml" };
        let mut args = strings(&["batch", name, "-o", "out/b", "--quiet"]);
        if rng.chance(0.3) {
            args.push("--jobs".into());
            args.push(rng.pick(&["2", "0", "1000000"]).to_string());
        }
        Case {
            target: Target::Batch,
            files: vec![
                (name.into(), text.into_bytes()),
                ("in/a.svg".into(), svg),
                ("images".into(), idx_images(3)),
            ],
            args,
            output: "out/b/summary.json".into(),
            mutations,
        }
    }

    /// A seed scene, mutated (JSON text, an image, paths).
    fn mutated_scene(&self, rng: &mut Rng) -> (Vec<(String, Vec<u8>)>, Vec<String>) {
        let mut files = if rng.chance(0.6) {
            synthetic_scene(rng, "scene")
        } else {
            ngp_scene(rng, "scene")
        };
        let mut mutations = Vec::new();
        for _ in 0..1 + rng.below(3) {
            let jsons: Vec<usize> = (0..files.len())
                .filter(|&k| files[k].0.ends_with(".json"))
                .collect();
            let pngs: Vec<usize> = (0..files.len())
                .filter(|&k| files[k].0.ends_with(".png"))
                .collect();
            match rng.below(10) {
                0..=5 => {
                    let k = *rng.pick(&jsons);
                    let m =
                        mutate_text_with(rng, &mut files[k].1, &[], &[], &JSON_EXTREMES, false, 2);
                    mutations.push(format!("{}: {m}", files[k].0));
                }
                6 => {
                    let k = *rng.pick(&jsons);
                    let evil = *rng.pick(&[
                        "../../../../etc/passwd",
                        "/etc/passwd",
                        "../outside",
                        "/dev/zero",
                        "",
                        ".",
                    ]);
                    let text = String::from_utf8_lossy(&files[k].1).into_owned();
                    let text = replace_nth_value(rng, &text, "\"file_path\": \"", evil);
                    files[k].1 = text.into_bytes();
                    mutations.push(format!("{}: a file_path → {evil:?}", files[k].0));
                }
                7 => {
                    let k = *rng.pick(&jsons);
                    let key = *rng.pick(&["camera_angle_x", "k1", "fl_x", "w", "cx"]);
                    let v = *rng.pick(&JSON_EXTREMES);
                    let text = String::from_utf8_lossy(&files[k].1).into_owned();
                    let text = text.replacen('{', &format!("{{\"{key}\": {v}, "), 1);
                    files[k].1 = text.into_bytes();
                    mutations.push(format!("{}: {key} = {v}", files[k].0));
                }
                _ => {
                    let k = *rng.pick(&pngs);
                    let m = mutate_png(rng, &mut files[k].1);
                    mutations.push(format!("{}: {m}", files[k].0));
                }
            }
        }
        (files, mutations)
    }

    fn case_recon(&self, rng: &mut Rng) -> Case {
        let (files, mut mutations) = self.mutated_scene(rng);
        let mut args = strings(&[
            "recon",
            "voxel",
            "--scene",
            "scene",
            "-o",
            "out/m.vox",
            "--iters",
            "2",
            "--res",
            "8",
            "--batch",
            "64",
            "--quiet",
        ]);
        if rng.chance(0.15) {
            let b = *rng.pick(&["1e30", "1e-30", "1e9", "NaN", "-1", "0.5"]);
            args.push(format!("--bound={b}"));
            mutations.push(format!("--bound {b}"));
        }
        if rng.chance(0.1) {
            let d = *rng.pick(&["2", "3", "1000000", "4294967295"]);
            args.push(format!("--downscale={d}"));
            mutations.push(format!("--downscale {d}"));
        }
        Case {
            target: Target::Recon,
            files,
            args,
            output: "out/m.vox".into(),
            mutations,
        }
    }

    fn case_view(&self, rng: &mut Rng) -> Case {
        let mut model = self.model.clone();
        let mut mutations = Vec::new();
        let (mut files, with_scene) = if rng.chance(0.5) {
            mutations.push(format!("model: {}", mutate_model(rng, &mut model)));
            (Vec::new(), false)
        } else {
            let (f, m) = self.mutated_scene(rng);
            mutations.extend(m);
            (f, true)
        };
        files.push(("m.vox".into(), model));
        let mut args = strings(&["view", "m.vox", "-o", "out/views"]);
        if with_scene {
            args.extend(strings(&["--scene", "scene"]));
        }
        if !with_scene || rng.chance(0.3) {
            let n = *rng.pick(&["2", "1", "3"]);
            args.extend(strings(&["--orbit", n]));
        }
        let output = if with_scene {
            "out/views/metrics.csv"
        } else {
            "out/views/orbit.gif"
        };
        Case {
            target: Target::View,
            files,
            args,
            output: output.into(),
            mutations,
        }
    }

    /// The fixed cases of issue 27, run before any random one: every [`REGION_SNIPPETS`]
    /// entry with every [`REGION_EXTREMES`] value through `render` (and once through
    /// `fit`), and pictures of one to three pixels a side through `vectorize` in each
    /// mode. A random campaign reaches the same inputs by chance; these reach them always.
    pub fn directed(&self) -> Vec<Case> {
        let mut cases = Vec::new();
        let svg = |body: &str| {
            format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64"><rect width="30" height="20" fill="teal"/>{body}</svg>"#
            )
            .into_bytes()
        };
        for snippet in REGION_SNIPPETS {
            for (k, x) in REGION_EXTREMES.iter().enumerate() {
                let body = snippet.replace("{X}", x);
                let mutations = vec![format!("directed: {body}")];
                let file = vec![("in.svg".to_string(), svg(&body))];
                cases.push(Case {
                    target: Target::Render,
                    files: file.clone(),
                    args: strings(&["render", "in.svg", "-o", "out/r.png", "--width", "64"]),
                    output: "out/r.png".into(),
                    mutations: mutations.clone(),
                });
                if k == 0 {
                    cases.push(Case {
                        target: Target::Fit,
                        files: file,
                        args: strings(&[
                            "fit",
                            "in.svg",
                            "in.svg",
                            "-o",
                            "out/f.svg",
                            "--iters",
                            "2",
                        ]),
                        output: "out/f.svg".into(),
                        mutations,
                    });
                }
            }
        }
        let mut rng = Rng::new(27);
        for (w, h) in [
            (1, 1),
            (1, 2),
            (2, 1),
            (2, 2),
            (2, 40),
            (40, 2),
            (3, 3),
            (1, 40),
        ] {
            let png = tiny_png(&mut rng, w, h);
            for mode in [
                &["--mode", "adaptive"][..],
                &["--mode", "fixed"],
                &["--mode", "painterly"],
                &["--target-psnr", "30", "--max-paths", "4", "--pyramid", "2"],
            ] {
                let mut args = strings(&["vectorize", "in.png", "-o", "out/v.svg", "--iters", "4"]);
                args.extend(strings(mode));
                cases.push(Case {
                    target: Target::Vectorize,
                    files: vec![("in.png".into(), png.clone())],
                    args,
                    output: "out/v.svg".into(),
                    mutations: vec![format!("directed: a {w}x{h} picture")],
                });
            }
        }
        cases
    }

    /// Runs every [`Fuzzer::directed`] case; they are numbered from [`DIRECTED_BASE`] in
    /// reports, apart from the random cases.
    pub fn run_directed(&mut self) -> Vec<Failure> {
        let cases = self.directed();
        cases
            .into_iter()
            .enumerate()
            .filter_map(|(k, case)| self.run(DIRECTED_BASE + k as u64, case))
            .collect()
    }

    /// Runs case `i`: `Some` when it broke the oracle (the reproducer saved when a
    /// folder was configured).
    pub fn run_case(&mut self, i: u64) -> Option<Failure> {
        let case = self.generate(i);
        self.run(i, case)
    }

    /// Runs one case, numbered `i` in the report.
    fn run(&mut self, i: u64, case: Case) -> Option<Failure> {
        let dir = self.cfg.work.join("case");
        let _ = std::fs::remove_dir_all(&dir);
        if let Err(e) = write_files(&dir, &case.files) {
            panic!("fuzzer cannot write its case: {e}");
        }
        std::fs::create_dir_all(dir.join("out")).expect("case out/ folder");
        let outcome = run_child(&self.cfg, &dir, &case.args);
        let problem = judge(&case, &dir, &outcome, &self.cfg);
        let st = self.stats.entry(case.target.name()).or_default();
        st[0] += 1;
        match (&problem, outcome.code) {
            (Some(_), _) => st[3] += 1,
            (None, Some(0)) => st[1] += 1,
            (None, _) => st[2] += 1,
        }
        if std::env::var_os("DIFFSVG_FUZZ_VERBOSE").is_some() {
            let last = outcome
                .stderr
                .lines()
                .rev()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("");
            eprintln!(
                "case {i} {} exit {:?}: {last} [{}]",
                case.target.name(),
                outcome.code,
                case.mutations.join("; ")
            );
        }
        let key = problem?;
        let key = format!("{}: {key}", case.target.name());
        let mut detail = String::new();
        let _ = write!(
            detail,
            "exit {:?}{}, {:.2} s, peak {} MiB; mutations: {}",
            outcome.code,
            if outcome.timed_out {
                " (timed out)"
            } else {
                ""
            },
            outcome.secs,
            outcome.peak_kib / 1024,
            case.mutations.join("; ")
        );
        let head = outcome
            .stderr
            .split("stack backtrace:")
            .next()
            .unwrap_or("");
        let tail: Vec<&str> = head.lines().rev().take(4).collect();
        if !tail.is_empty() {
            let tail: Vec<&str> = tail.into_iter().rev().collect();
            let _ = write!(detail, "\n  stderr: {}", tail.join("\n          "));
        }
        let command = format!("diffsvg {}", shell_words(&case.args));
        let saved = self.save(&key, i, &case, &command, &detail);
        Some(Failure {
            case: i,
            key,
            detail,
            command,
            saved,
        })
    }

    /// Copies the case's inputs and a `cmd.sh` into the reproducer folder.
    fn save(
        &mut self,
        key: &str,
        i: u64,
        case: &Case,
        command: &str,
        detail: &str,
    ) -> Option<PathBuf> {
        let root = self.cfg.repro_dir.clone()?;
        let n = self.saved.entry(key.to_string()).or_default();
        if *n >= self.cfg.repro_per_kind {
            return None;
        }
        *n += 1;
        let slug: String = key
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
            .collect::<String>()
            .split('-')
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join("-");
        let slug: String = slug.chars().take(80).collect();
        let dir = root.join(format!("{slug}-seed{}-case{i}", self.cfg.seed));
        let _ = std::fs::remove_dir_all(&dir);
        write_files(&dir, &case.files).ok()?;
        let script = format!(
            "#!/bin/sh\n# {key}\n# fuzz seed {} case {i}\n# {}\ncd \"$(dirname \"$0\")\" && mkdir -p out && ulimit -v {} && exec \"${{DIFFSVG:-diffsvg}}\" {}\n",
            self.cfg.seed,
            detail.replace('\n', "\n# "),
            self.cfg.mem_limit_kib,
            shell_words(&case.args)
        );
        let _ = command;
        std::fs::write(dir.join("cmd.sh"), script).ok()?;
        Some(dir)
    }
}

/// Decides whether an outcome breaks the oracle; the failure's kind when it does.
fn judge(case: &Case, dir: &Path, o: &Outcome, cfg: &Config) -> Option<String> {
    let err = &o.stderr;
    if let Some(at) = err.find("panicked at ") {
        let rest = &err[at + "panicked at ".len()..];
        let loc = rest.split([':', '\n']).next().unwrap_or("");
        let line = rest.split(':').nth(1).unwrap_or("");
        return Some(format!("panic at {loc}:{line}"));
    }
    if err.contains("has overflowed its stack") {
        return Some("stack overflow".into());
    }
    if err.contains("memory allocation of") {
        return Some(format!(
            "abort: memory allocation failed{}",
            first_frame(err)
        ));
    }
    if o.timed_out {
        return Some(format!("timeout (over {} s)", cfg.timeout.as_secs()));
    }
    let Some(code) = o.code else {
        return Some("killed by a signal".into());
    };
    let allowed: &[i32] = if case.target == Target::Batch {
        &[0, 1, 2]
    } else {
        &[0, 2]
    };
    if !allowed.contains(&code) {
        return Some(format!("exit status {code}"));
    }
    if code == 2 {
        let last = err
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("");
        if !last.starts_with("error: ") {
            return Some("exit 2 without an error line".into());
        }
    }
    if o.peak_kib > cfg.rss_ceiling_kib {
        return Some(format!("memory over {} MiB", cfg.rss_ceiling_kib / 1024));
    }
    let out = dir.join("out");
    let left = files_under(&out);
    if code == 2 || (code != 0 && case.target != Target::Batch) {
        if !left.is_empty() {
            return Some("output left after a failure".into());
        }
    } else if code == 0 && !dir.join(&case.output).is_file() {
        return Some("exit 0 without its output".into());
    }
    if let Some(tmp) = left.iter().find(|p| p.to_string_lossy().ends_with(".tmp")) {
        let _ = tmp;
        return Some("temporary file left".into());
    }
    if case.target == Target::Batch && code != 2 {
        let summary = std::fs::read_to_string(dir.join(&case.output)).unwrap_or_default();
        for needle in [
            "panicked at",
            "memory allocation of",
            "signal",
            "overflowed its stack",
        ] {
            if summary.contains(needle) {
                return Some(format!("a job died ({needle})"));
            }
        }
    }
    None
}

/// ` in <function>`: the innermost diffsvg frame of a backtrace on stderr, if any.
fn first_frame(err: &str) -> String {
    err.lines()
        .skip_while(|l| !l.starts_with("stack backtrace:"))
        .filter_map(|l| l.trim().split_once(": ").map(|(_, f)| f))
        .find(|f| f.starts_with("diffsvg::"))
        .map(|f| {
            let f = f.replace("::{{closure}}", "");
            let f = f.split("::h").next().unwrap_or(&f).to_string();
            format!(" in {f}")
        })
        .unwrap_or_default()
}

/// Every regular file below `dir`.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else {
        return out;
    };
    for e in rd.flatten() {
        let p = e.path();
        match e.file_type() {
            Ok(t) if t.is_dir() => out.extend(files_under(&p)),
            Ok(_) => out.push(p),
            Err(_) => {}
        }
    }
    out
}

/// Runs the binary in `dir` under `ulimit -v`, with a time limit, polling its peak
/// resident memory.
pub fn run_child(cfg: &Config, dir: &Path, args: &[String]) -> Outcome {
    use std::os::unix::process::CommandExt;
    let t0 = Instant::now();
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v {} && exec \"$0\" \"$@\"",
            cfg.mem_limit_kib
        ))
        .arg(&cfg.bin)
        .args(args)
        .current_dir(dir)
        // Few threads and malloc arenas, so that the address-space limit measures the
        // work rather than per-thread reservations.
        .env("RAYON_NUM_THREADS", "2")
        .env("MALLOC_ARENA_MAX", "2")
        // A backtrace tells distinct allocation failures apart.
        .env("RUST_BACKTRACE", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .process_group(0)
        .spawn()
        .expect("runs sh");
    let pid = child.id();
    let mut stderr = child.stderr.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let mut chunk = [0u8; 8192];
        loop {
            match stderr.read(&mut chunk) {
                Ok(0) | Err(_) => break,
                Ok(n) => {
                    if buf.len() < 1 << 16 {
                        buf.extend_from_slice(&chunk[..n]);
                    }
                }
            }
        }
        String::from_utf8_lossy(&buf).into_owned()
    });
    let status_path = format!("/proc/{pid}/status");
    let mut peak = 0u64;
    let mut timed_out = false;
    let status = loop {
        if let Ok(s) = std::fs::read_to_string(&status_path)
            && let Some(kib) = s
                .lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse::<u64>().ok())
        {
            peak = peak.max(kib);
        }
        match child.try_wait() {
            Ok(Some(st)) => break Some(st),
            Ok(None) => {}
            Err(_) => break None,
        }
        if t0.elapsed() > cfg.timeout {
            timed_out = true;
            // The whole process group: batch's children too.
            let _ = Command::new("kill")
                .args(["-KILL", "--", &format!("-{pid}")])
                .status();
            let _ = child.kill();
            break child.wait().ok();
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let stderr = reader.join().unwrap_or_default();
    Outcome {
        code: status.and_then(|s| s.code()),
        timed_out,
        stderr,
        peak_kib: peak,
        secs: t0.elapsed().as_secs_f64(),
    }
}

/// Runs cases `first..first + n` (or until `deadline`), returning the failures.
pub fn campaign(
    fz: &mut Fuzzer,
    first: u64,
    n: u64,
    deadline: Option<Instant>,
    mut progress: impl FnMut(u64, &[Failure]),
) -> (u64, Vec<Failure>) {
    let mut failures = Vec::new();
    let mut run = 0;
    for i in first..first.saturating_add(n) {
        if deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        if let Some(f) = fz.run_case(i) {
            failures.push(f);
        }
        run += 1;
        progress(run, &failures);
    }
    (run, failures)
}

/// Distinct failure keys with their counts and first case.
pub fn distinct(failures: &[Failure]) -> BTreeMap<String, (usize, &Failure)> {
    let mut m: BTreeMap<String, (usize, &Failure)> = BTreeMap::new();
    for f in failures {
        m.entry(f.key.clone()).or_insert((0, f)).0 += 1;
    }
    m
}

// ---- inputs -------------------------------------------------------------------------

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn shell_words(args: &[String]) -> String {
    args.iter()
        .map(|a| {
            if !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./,=:+".contains(c))
            {
                a.clone()
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

fn collect_svgs(base: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = rd.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            collect_svgs(base, &p, out);
        } else if p.extension().is_some_and(|e| e == "svg")
            && let Ok(b) = std::fs::read(&p)
            && b.len() <= 256 << 10
        {
            let name = p.strip_prefix(base).unwrap_or(&p).display().to_string();
            out.push((name, b));
        }
    }
}

fn write_files(dir: &Path, files: &[(String, Vec<u8>)]) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for (name, bytes) in files {
        let p = dir.join(name);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        }
        std::fs::write(&p, bytes).map_err(|e| format!("{}: {e}", p.display()))?;
    }
    Ok(())
}

/// A small RGBA PNG with a few shapes.
fn tiny_png(rng: &mut Rng, w: u32, h: u32) -> Vec<u8> {
    let (a, b) = (rng.next_u64() as u32, rng.next_u64() as u32);
    let img = image::RgbaImage::from_fn(w, h, |x, y| {
        let inside = (x * 3 + y * 5 + a) % 17 < 9;
        let v = (b >> ((x + y) % 24)) as u8;
        image::Rgba(if inside {
            [v, 255 - v, 80, 255]
        } else {
            [250, 250, 250, 255]
        })
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("encodes PNG");
    out.into_inner()
}

/// An IDX3 file of `n` 28×28 digits (a bar at a place depending on the index).
fn idx_images(n: u32) -> Vec<u8> {
    let mut v = vec![0, 0, 8, 3];
    for d in [n, 28, 28] {
        v.extend_from_slice(&d.to_be_bytes());
    }
    for i in 0..n {
        for y in 0..28u32 {
            for x in 0..28u32 {
                let on = (6..22).contains(&y) && x.abs_diff(10 + 3 * i) < 3;
                v.push(if on { 255 } else { 0 });
            }
        }
    }
    v
}

/// An IDX1 label file of `n` labels.
fn idx_labels(n: u32) -> Vec<u8> {
    let mut v = vec![0, 0, 8, 1];
    v.extend_from_slice(&n.to_be_bytes());
    v.extend((0..n).map(|i| (i % 10) as u8));
    v
}

/// Images claimed by the gzip bomb: 400 000 × 784 bytes = 314 MB of zeros once inflated,
/// past `limits::MAX_DECOMPRESSED_BYTES`.
const BOMB_IMAGES: u32 = 400_000;

/// The bomb's header: a valid IDX3 header for [`BOMB_IMAGES`] 28×28 images.
fn idx_bomb() -> Vec<u8> {
    let mut v = vec![0, 0, 8, 3];
    for d in [BOMB_IMAGES, 28, 28] {
        v.extend_from_slice(&d.to_be_bytes());
    }
    v
}

/// Gzips `bytes`; after the bomb's header, streams its zero pixels.
fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(bytes).expect("gzip");
    if bytes == idx_bomb().as_slice() {
        let zeros = vec![0u8; 784 * 1000];
        for _ in 0..BOMB_IMAGES / 1000 {
            enc.write_all(&zeros).expect("gzip");
        }
    }
    enc.finish().expect("gzip")
}

/// Row-major 4×4 pose of a camera at angle `a` on a circle of radius 4, looking at the
/// origin (OpenGL axes).
fn pose_rows(a: f64) -> String {
    let eye = [4.0 * a.cos(), 4.0 * a.sin(), 1.0];
    let norm = |v: [f64; 3]| {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / l, v[1] / l, v[2] / l]
    };
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let f = norm([-eye[0], -eye[1], -eye[2]]);
    let r = norm(cross(f, [0.0, 0.0, 1.0]));
    let u = cross(r, f);
    let z = [-f[0], -f[1], -f[2]];
    format!(
        "[[{}, {}, {}, {}], [{}, {}, {}, {}], [{}, {}, {}, {}], [0, 0, 0, 1]]",
        r[0], u[0], z[0], eye[0], r[1], u[1], z[1], eye[1], r[2], u[2], z[2], eye[2]
    )
}

/// A NeRF-synthetic folder: 2 train and 1 test views of 8×8 under `dir/`.
fn synthetic_scene(rng: &mut Rng, dir: &str) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    for (split, n, off) in [("train", 2, 0.0), ("test", 1, 2.0)] {
        let frames: Vec<String> = (0..n)
            .map(|i| {
                files.push((format!("{dir}/{split}/r_{i}.png"), tiny_png(rng, 8, 8)));
                format!(
                    "{{\"file_path\": \"./{split}/r_{i}\", \"rotation\": 0.01, \"transform_matrix\": {}}}",
                    pose_rows(0.7 * (i as f64 + off))
                )
            })
            .collect();
        let json = format!(
            "{{\"camera_angle_x\": 0.6911112070083618, \"frames\": [{}]}}",
            frames.join(", ")
        );
        files.push((format!("{dir}/transforms_{split}.json"), json.into_bytes()));
    }
    files
}

/// An instant-ngp folder: 3 views of 8×6 with intrinsics and distortion under `dir/`.
fn ngp_scene(rng: &mut Rng, dir: &str) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    let frames: Vec<String> = (0..3)
        .map(|i| {
            files.push((format!("{dir}/images/{i:04}.png"), tiny_png(rng, 8, 6)));
            format!(
                "{{\"file_path\": \"images/{i:04}.png\", \"sharpness\": 30.0, \"transform_matrix\": {}}}",
                pose_rows(0.5 * i as f64)
            )
        })
        .collect();
    let json = format!(
        "{{\"fl_x\": 12.0, \"fl_y\": 11.0, \"cx\": 4.0, \"cy\": 3.0, \"w\": 8, \"h\": 6, \
         \"k1\": 0.05, \"k2\": -0.08, \"p1\": -0.001, \"p2\": 0.0002, \"aabb_scale\": 4, \
         \"frames\": [{}]}}",
        frames.join(", ")
    );
    files.push((format!("{dir}/transforms.json"), json.into_bytes()));
    files
}

/// Replaces the value after one random occurrence of `prefix` (up to the next `"`).
fn replace_nth_value(rng: &mut Rng, text: &str, prefix: &str, value: &str) -> String {
    let starts: Vec<usize> = text
        .match_indices(prefix)
        .map(|(i, _)| i + prefix.len())
        .collect();
    if starts.is_empty() {
        return text.to_string();
    }
    let s = *rng.pick(&starts);
    let e = text[s..].find('"').map(|k| s + k).unwrap_or(text.len());
    format!("{}{}{}", &text[..s], value, &text[e..])
}

// ---- mutations ----------------------------------------------------------------------

/// Byte ranges of the numbers in `t` (`-1.5e3`, `.5`, `7`).
fn numbers(t: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < t.len() {
        let c = t[i];
        let starts = c.is_ascii_digit()
            || (c == b'.' && t.get(i + 1).is_some_and(u8::is_ascii_digit))
            || (c == b'-'
                && t.get(i + 1)
                    .is_some_and(|d| d.is_ascii_digit() || *d == b'.'));
        if starts && (i == 0 || !t[i - 1].is_ascii_alphanumeric()) {
            let s = i;
            i += 1;
            while i < t.len()
                && (t[i].is_ascii_digit()
                    || t[i] == b'.'
                    || ((t[i] == b'e' || t[i] == b'E')
                        && t.get(i + 1)
                            .is_some_and(|d| d.is_ascii_digit() || *d == b'-')))
            {
                if t[i] == b'e' || t[i] == b'E' {
                    i += 1;
                }
                i += 1;
            }
            out.push((s, i));
        } else {
            i += 1;
        }
    }
    out
}

/// One generic mutation of bytes: flip, insert, delete, duplicate, splice, or a
/// dictionary insert.
fn mutate_bytes(rng: &mut Rng, b: &mut Vec<u8>, donor: &[u8]) -> String {
    let len = b.len();
    match rng.below(6) {
        0 if len > 0 => {
            let k = rng.below(len);
            let bit = rng.below(8);
            b[k] ^= 1 << bit;
            format!("flip bit {bit} of byte {k}")
        }
        1 => {
            let k = rng.below(len + 1);
            let n = 1 + rng.below(8);
            let bytes: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
            b.splice(k..k, bytes);
            format!("insert {n} random bytes at {k}")
        }
        2 if len > 0 => {
            let k = rng.below(len);
            let n = (1 + rng.below(64)).min(len - k);
            b.drain(k..k + n);
            format!("delete {n} bytes at {k}")
        }
        3 if len > 0 => {
            let k = rng.below(len);
            let n = (1 + rng.below(256)).min(len - k);
            let chunk = b[k..k + n].to_vec();
            let at = rng.below(len + 1);
            b.splice(at..at, chunk);
            format!("copy {n} bytes from {k} to {at}")
        }
        4 if !donor.is_empty() => {
            let k = rng.below(donor.len());
            let n = (1 + rng.below(512)).min(donor.len() - k);
            let at = rng.below(len + 1);
            b.splice(at..at, donor[k..k + n].iter().copied());
            format!("splice {n} bytes of another seed at {at}")
        }
        _ if len > 0 => {
            let k = rng.below(len);
            b.truncate(k);
            format!("truncate to {k} bytes")
        }
        _ => {
            b.push(b'<');
            "append <".into()
        }
    }
}

/// One text mutation: a number replaced by an extreme, a snippet inserted, or a byte
/// mutation.
fn mutate_text(rng: &mut Rng, b: &mut Vec<u8>, donor: &[u8], snippets: &[&str]) -> String {
    mutate_text_with(rng, b, donor, snippets, &EXTREMES, false, 3)
}

/// [`mutate_text`] with its own extremes, snippets inserted at line starts when
/// `lines`, and byte mutations in `bytes_in_10` of 10 cases.
fn mutate_text_with(
    rng: &mut Rng,
    b: &mut Vec<u8>,
    donor: &[u8],
    snippets: &[&str],
    extremes: &[&str],
    lines: bool,
    bytes_in_10: usize,
) -> String {
    let nums = numbers(b);
    let roll = rng.below(10);
    let text_roll = if roll < 10 - bytes_in_10 {
        roll * 7 / (10 - bytes_in_10).max(1)
    } else {
        9
    };
    match text_roll {
        0..=4 if !nums.is_empty() => {
            let (s, e) = *rng.pick(&nums);
            let old = String::from_utf8_lossy(&b[s..e]).into_owned();
            let new = *rng.pick(extremes);
            b.splice(s..e, new.bytes());
            format!("number {old} → {new}")
        }
        5 | 6 if !snippets.is_empty() => {
            let snip = *rng.pick(snippets);
            let mut k = rng.below(b.len() + 1);
            if lines {
                let starts: Vec<usize> = (0..b.len())
                    .filter(|&i| i == 0 || b[i - 1] == b'\n')
                    .collect();
                k = *rng.pick(&starts);
            }
            b.splice(k..k, snip.bytes());
            format!("insert {snip:?} at {k}")
        }
        _ => mutate_bytes(rng, b, donor),
    }
}

/// One SVG mutation: any text mutation, an element duplicated many times, content
/// nested in groups, attribute values swapped, or a hostile attribute injected.
fn mutate_svg(rng: &mut Rng, svg: &mut Vec<u8>, donor: &[u8]) -> String {
    let text = String::from_utf8_lossy(svg).into_owned();
    // Element starts (`<name`), skipping the root `<svg`.
    let starts: Vec<usize> = text
        .match_indices('<')
        .map(|(i, _)| i)
        .filter(|&i| {
            text[i + 1..].starts_with(|c: char| c.is_ascii_alphabetic())
                && !text[i + 1..].starts_with("svg")
        })
        .collect();
    match rng.below(14) {
        0..=4 => mutate_text(rng, svg, donor, &SVG_SNIPPETS),
        12 if !starts.is_empty() => {
            // Every number of one element (all its attributes) replaced by one extreme.
            let s = *rng.pick(&starts);
            let e = text[s..].find('>').map_or(text.len(), |k| s + k);
            let extreme = *rng.pick(&EXTREMES);
            let el = &text.as_bytes()[s..e];
            let mut out = Vec::with_capacity(el.len());
            let mut last = 0;
            for (a, b) in numbers(el) {
                out.extend_from_slice(&el[last..a]);
                out.extend_from_slice(extreme.as_bytes());
                last = b;
            }
            out.extend_from_slice(&el[last..]);
            let mut bytes = text.as_bytes()[..s].to_vec();
            bytes.extend_from_slice(&out);
            bytes.extend_from_slice(&text.as_bytes()[e..]);
            *svg = bytes;
            let name: String = text[s..e].chars().take(24).collect();
            format!("every number of {name:?} → {extreme}")
        }
        13 => {
            // A region or far arc appended before the closing tag.
            let snippet = *rng.pick(&REGION_SNIPPETS);
            let extreme = *rng.pick(&EXTREMES);
            let el = snippet.replace("{X}", extreme);
            let at = text.rfind("</svg>").unwrap_or(text.len());
            *svg = format!("{}{el}{}", &text[..at], &text[at..]).into_bytes();
            format!("append {el:?}")
        }
        5 if !starts.is_empty() => {
            // Duplicate a self-closing element N times.
            let s = *rng.pick(&starts);
            let e = match text[s..].find('>') {
                Some(k) if text[s..s + k].ends_with('/') => s + k + 1,
                _ => return mutate_text(rng, svg, donor, &SVG_SNIPPETS),
            };
            let n = *rng.pick(&[2usize, 10, 100, 1000, 20000]);
            let el = &text[s..e];
            let rep = el.repeat(n);
            *svg = format!("{}{}{}", &text[..s], rep, &text[e..]).into_bytes();
            format!("element {:?} ×{n}", el.chars().take(40).collect::<String>())
        }
        6 => {
            // Nest the content in K groups.
            let open_end = text
                .find("<svg")
                .and_then(|s| text[s..].find('>').map(|k| s + k + 1));
            let close = text.rfind("</svg>");
            let (Some(a), Some(z)) = (open_end, close) else {
                return mutate_text(rng, svg, donor, &SVG_SNIPPETS);
            };
            if a > z {
                return mutate_text(rng, svg, donor, &SVG_SNIPPETS);
            }
            let k = *rng.pick(&[2usize, 50, 100, 300, 1000]);
            let g = *rng.pick(&[
                "<g opacity=\"0.9\">",
                "<g>",
                "<g transform=\"scale(2)\">",
                "<g style=\"opacity:0.5\">",
            ]);
            *svg = format!(
                "{}{}{}{}{}",
                &text[..a],
                g.repeat(k),
                &text[a..z],
                "</g>".repeat(k),
                &text[z..]
            )
            .into_bytes();
            format!("content nested in {k} × {g}")
        }
        7 => {
            // Swap the values of two attributes.
            let vals: Vec<(usize, usize)> = text
                .match_indices("=\"")
                .filter_map(|(i, _)| text[i + 2..].find('"').map(|k| (i + 2, i + 2 + k)))
                .collect();
            if vals.len() < 2 {
                return mutate_text(rng, svg, donor, &SVG_SNIPPETS);
            }
            let (mut x, mut y) = (*rng.pick(&vals), *rng.pick(&vals));
            if x.0 > y.0 {
                std::mem::swap(&mut x, &mut y);
            }
            if x.1 >= y.0 {
                return mutate_text(rng, svg, donor, &SVG_SNIPPETS);
            }
            *svg = format!(
                "{}{}{}{}{}",
                &text[..x.0],
                &text[y.0..y.1],
                &text[x.1..y.0],
                &text[x.0..x.1],
                &text[y.1..]
            )
            .into_bytes();
            "two attribute values swapped".into()
        }
        _ if !starts.is_empty() => {
            // Inject a hostile attribute after an element's name.
            let s = *rng.pick(&starts);
            let name_end = text[s + 1..]
                .find(|c: char| c.is_whitespace() || c == '>' || c == '/')
                .map(|k| s + 1 + k)
                .unwrap_or(text.len());
            let attr = *rng.pick(&ATTRS);
            *svg = format!("{} {attr} {}", &text[..name_end], &text[name_end..]).into_bytes();
            format!("{} gets {attr}", &text[s..name_end])
        }
        _ => mutate_text(rng, svg, donor, &SVG_SNIPPETS),
    }
}

/// One IDX mutation: a header field replaced, the type or rank byte changed, or a byte
/// mutation.
fn mutate_idx(rng: &mut Rng, b: &mut Vec<u8>) -> String {
    if b.len() >= 16 && b[3] == 3 && rng.chance(0.3) {
        // A consistent file of another shape.
        let (n, h, w) = *rng.pick(&[
            (0u32, 28u32, 28u32),
            (1, 1, 1),
            (2, 0, 28),
            (1, 255, 255),
            (3, 28, 1),
            (50, 28, 28),
            (1, 4096, 1),
        ]);
        let mut v = vec![0, 0, 8, 3];
        for d in [n, h, w] {
            v.extend_from_slice(&d.to_be_bytes());
        }
        let size = (n * h * w) as usize;
        v.extend((0..size).map(|i| if (i * 7) % 13 < 5 { 255 } else { 0 }));
        *b = v;
        return format!("a consistent {n}×{h}×{w} file");
    }
    match rng.below(4) {
        0 | 1 if b.len() >= 8 => {
            let fields = ((b.len() - 4) / 4).min(3);
            let f = 1 + rng.below(fields.max(1));
            let v = *rng.pick(&[0u32, 1, 2, 27, 29, 65536, 100_000, 0x7fff_ffff, u32::MAX]);
            b[4 * f..4 * f + 4].copy_from_slice(&v.to_be_bytes());
            format!("header field {f} → {v}")
        }
        2 if b.len() >= 4 => {
            let k = 2 + rng.below(2);
            let v = *rng.pick(&[0u8, 1, 2, 3, 4, 9, 0x0d, 255]);
            b[k] = v;
            format!("header byte {k} → {v}")
        }
        _ => mutate_bytes(rng, b, &[]),
    }
}

/// One voxel-model mutation: a header field (bounds, resolution, degree) or a body
/// value overwritten in place by an extreme, or a byte mutation.
fn mutate_model(rng: &mut Rng, b: &mut Vec<u8>) -> String {
    if b.len() < 48 || rng.chance(0.2) {
        return mutate_bytes(rng, b, &[]);
    }
    let at = if rng.chance(0.6) {
        12 + 4 * rng.below(8)
    } else {
        4 * rng.below(b.len() / 4)
    };
    let (bytes, what) = if (36..44).contains(&at) {
        let v = *rng.pick(&[0u32, 1, 7, 9, 4, 1024, 65536, u32::MAX]);
        (v.to_le_bytes(), v.to_string())
    } else {
        let v = *rng.pick(&[
            f32::NAN,
            f32::INFINITY,
            -f32::INFINITY,
            1e30,
            -1e30,
            0.0,
            1e-30,
            f32::MAX,
        ]);
        (v.to_le_bytes(), v.to_string())
    };
    b[at..at + 4].copy_from_slice(&bytes);
    format!("4 bytes at {at} → {what}")
}

/// One PNG mutation: the IHDR size patched (with a valid CRC) to something huge, or a
/// byte mutation.
fn mutate_png(rng: &mut Rng, b: &mut Vec<u8>) -> String {
    if b.len() >= 33 && &b[12..16] == b"IHDR" && rng.chance(0.5) {
        let w = *rng.pick(&[0u32, 1, 11000, 20000, 65535, 1 << 20, 0x7fff_ffff]);
        let h = *rng.pick(&[1u32, 11000, 20000, 1 << 20]);
        b[16..20].copy_from_slice(&w.to_be_bytes());
        b[20..24].copy_from_slice(&h.to_be_bytes());
        let crc = crc32(&b[12..29]);
        b[29..33].copy_from_slice(&crc.to_be_bytes());
        return format!("PNG header says {w}×{h}");
    }
    mutate_bytes(rng, b, &[])
}

/// CRC-32 (IEEE), as PNG chunks use it.
fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &x in data {
        c ^= x as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_matches_png() {
        // IEND's CRC.
        assert_eq!(crc32(b"IEND"), 0xae42_6082);
    }
}
