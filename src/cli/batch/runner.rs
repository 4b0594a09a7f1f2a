//! Running one job: the resume check, the child process, its figures and the manifest.

use std::path::{Component, Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::figures;
use super::jobfile::Job;
use diffsvg::image_io::write_atomic;

/// The manifest's file name inside a job folder; written last, atomically.
pub const MANIFEST: &str = "manifest.json";
/// The job's figures, beside the manifest.
pub const RESULT: &str = "result.json";

/// What every job shares.
#[derive(Debug, Clone)]
pub struct Context {
    /// The root output folder; a job writes into `<root>/<job name>/`.
    pub root: PathBuf,
    /// The `diffsvg` binary the children run.
    pub exe: PathBuf,
    /// `RAYON_NUM_THREADS` for each child.
    pub threads: usize,
    /// Skip jobs whose manifest shows they are complete.
    pub resume: bool,
    /// With `resume`, rerun jobs recorded as failed.
    pub retry_failed: bool,
}

/// How a job ended.
#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Debug)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Ran and succeeded.
    Ok,
    /// Failed (now or, with `cached`, in the run its manifest records).
    Failed,
    /// Complete from an earlier run (`--resume`); figures come from its manifest.
    Skipped,
}

/// One job's result: a line of the summary, `result.json`, a JSON progress line.
#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct Outcome {
    /// Position of the job after glob expansion.
    pub index: usize,
    /// The job's name (its folder).
    pub name: String,
    /// The subcommand.
    pub kind: String,
    /// ok, failed or skipped.
    pub status: Status,
    /// Taken from an earlier run's manifest instead of run now.
    pub cached: bool,
    /// PSNR of the result in dB, when the subcommand measures one.
    pub psnr: Option<f64>,
    /// Number of paths of the result (render: of the input).
    pub paths: Option<u64>,
    /// Wall-clock time of the job in seconds.
    pub seconds: f64,
    /// Why it failed.
    pub error: Option<String>,
    /// Input files as the job file names them.
    pub inputs: Vec<String>,
    /// The main output, relative to the output root.
    pub output: Option<String>,
    /// Every file the job wrote, relative to the output root.
    pub outputs: Vec<String>,
    /// The thumbnail, relative to the output root.
    pub thumbnail: Option<String>,
    /// Stopped by a signal or Ctrl-C: not recorded, so that `--resume` runs it again.
    #[serde(skip)]
    pub interrupted: bool,
}

impl Outcome {
    fn new(job: &Job) -> Self {
        Outcome {
            index: job.index,
            name: job.name.clone(),
            kind: job.kind.clone(),
            status: Status::Failed,
            cached: false,
            psnr: None,
            paths: None,
            seconds: 0.0,
            error: None,
            inputs: job.shown_inputs.clone(),
            output: None,
            outputs: Vec::new(),
            thumbnail: None,
            interrupted: false,
        }
    }

    /// Whether the job counts as a failure for the exit code.
    pub fn failed(&self) -> bool {
        self.status == Status::Failed
    }
}

/// What the manifest records about a job.
#[derive(Serialize, Deserialize)]
struct Manifest {
    diffsvg: String,
    kind: String,
    name: String,
    args: Vec<String>,
    inputs: Vec<InputHash>,
    outputs: Vec<OutputFile>,
    result: Outcome,
}

/// An input file and the SHA-256 of its bytes (`None`: it could not be read).
#[derive(Serialize, Deserialize, PartialEq, Eq, Debug, Clone)]
struct InputHash {
    path: String,
    sha256: Option<String>,
}

/// An output file, relative to the job folder.
#[derive(Serialize, Deserialize)]
struct OutputFile {
    path: String,
    size: u64,
    sha256: String,
}

/// How the child process ended.
enum Ended {
    Ok(String),
    Failed(String),
    Interrupted(String),
}

/// Runs one job (or takes it from its manifest with `--resume`). Never panics on bad
/// input: every failure becomes a failed outcome.
pub fn run(job: &Job, ctx: &Context) -> Outcome {
    let dir = ctx.root.join(&job.name);
    let hashed: Vec<(InputHash, Option<String>)> =
        job.inputs.iter().map(|p| hash_input(p)).collect();
    let hashes: Vec<InputHash> = hashed.iter().map(|(h, _)| h.clone()).collect();
    let earlier = ctx
        .resume
        .then(|| cached(job, &dir, &hashes, ctx.retry_failed));
    if let Some(o) = earlier.flatten() {
        return o;
    }
    let start = Instant::now();
    let mut o = Outcome::new(job);
    let unreadable = hashed.into_iter().find_map(|(_, e)| e);
    let ended = match (job.error.clone(), unreadable) {
        (Some(e), _) | (None, Some(e)) => {
            // Still clear an older run's outputs, so the folder matches this record.
            let _ = prepare(&dir);
            Ended::Failed(e)
        }
        (None, None) => match prepare(&dir) {
            Ok(()) => execute(job, ctx, &dir),
            Err(e) => Ended::Failed(e),
        },
    };
    let stdout = match ended {
        Ended::Ok(s) => s,
        Ended::Failed(e) => {
            o.error = Some(e);
            return finish(job, &dir, o, hashes, start);
        }
        Ended::Interrupted(e) => {
            o.error = Some(e);
            o.interrupted = true;
            o.seconds = start.elapsed().as_secs_f64();
            return o;
        }
    };
    o.status = Status::Ok;
    let f = figures::inspect(job, &dir, &stdout);
    o.psnr = f.psnr;
    o.paths = f.paths;
    if f.thumbnail {
        o.thumbnail = Some(format!("{}/{}", job.name, figures::THUMB));
    }
    o.output = Some(match &job.output {
        Some(out) => format!("{}/{out}", job.name),
        None => format!("{}/", job.name),
    });
    finish(job, &dir, o, hashes, start)
}

/// Records a finished job: `result.json`, then the manifest (atomically, last).
fn finish(
    job: &Job,
    dir: &Path,
    mut o: Outcome,
    inputs: Vec<InputHash>,
    start: Instant,
) -> Outcome {
    let outputs = list_outputs(dir);
    o.outputs = outputs
        .iter()
        .map(|f| format!("{}/{}", job.name, f.path))
        .collect();
    o.seconds = start.elapsed().as_secs_f64();
    let manifest = Manifest {
        diffsvg: env!("CARGO_PKG_VERSION").into(),
        kind: job.kind.clone(),
        name: job.name.clone(),
        args: job.args.clone(),
        inputs,
        outputs,
        result: o.clone(),
    };
    let written = std::fs::create_dir_all(dir)
        .map_err(|e| e.to_string())
        .and_then(|()| write_json(&dir.join(RESULT), &o))
        .and_then(|()| write_json(&dir.join(MANIFEST), &manifest));
    if let Err(e) = written {
        o.status = Status::Failed;
        o.error = Some(match o.error.take() {
            Some(first) => format!("{first}; and: {e}"),
            None => e,
        });
    }
    o
}

fn write_json<T: Serialize>(path: &Path, v: &T) -> Result<(), String> {
    let text = serde_json::to_string_pretty(v).map_err(|e| e.to_string())?;
    write_atomic(path, text.as_bytes()).map_err(|e| e.to_string())
}

/// The earlier outcome, when the manifest shows the same arguments and inputs and (for a
/// job that succeeded) every output still there.
fn cached(job: &Job, dir: &Path, inputs: &[InputHash], retry_failed: bool) -> Option<Outcome> {
    let m = read_manifest(dir)?;
    if m.kind != job.kind || m.args != job.args || m.inputs != inputs {
        return None;
    }
    let mut o = m.result;
    o.index = job.index;
    o.cached = true;
    match o.status {
        Status::Failed if retry_failed => None,
        Status::Failed => Some(o),
        Status::Ok | Status::Skipped => {
            let complete = m.outputs.iter().all(|f| {
                safe_relative(&f.path)
                    && std::fs::metadata(dir.join(&f.path)).is_ok_and(|md| md.len() == f.size)
            });
            o.status = Status::Skipped;
            complete.then_some(o)
        }
    }
}

fn read_manifest(dir: &Path) -> Option<Manifest> {
    let bytes =
        diffsvg::image_io::read_bounded(&dir.join(MANIFEST), diffsvg::limits::MAX_FILE_BYTES)
            .ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// Makes the job folder and clears what an earlier run recorded there: the manifest first
/// (so an interrupted rerun is never taken for complete), then its outputs.
fn prepare(dir: &Path) -> Result<(), String> {
    let old = read_manifest(dir);
    let _ = std::fs::remove_file(dir.join(MANIFEST));
    if let Some(m) = old {
        for f in m.outputs.iter().filter(|f| safe_relative(&f.path)) {
            let _ = std::fs::remove_file(dir.join(&f.path));
        }
    }
    let _ = std::fs::remove_file(dir.join(RESULT));
    let _ = std::fs::remove_file(dir.join(figures::THUMB));
    std::fs::create_dir_all(dir)
        .map_err(|e| format!("{}: cannot create the job folder: {e}", dir.display()))
}

/// A manifest path that stays inside the job folder.
fn safe_relative(p: &str) -> bool {
    Path::new(p)
        .components()
        .all(|c| matches!(c, Component::Normal(_)))
}

/// Runs the job's subcommand as a child process in the job folder.
fn execute(job: &Job, ctx: &Context, dir: &Path) -> Ended {
    let out = Command::new(&ctx.exe)
        .args(&job.args)
        .current_dir(dir)
        .env("RAYON_NUM_THREADS", ctx.threads.to_string())
        .stdin(Stdio::null())
        .output();
    let out = match out {
        Ok(o) => o,
        Err(e) => return Ended::Failed(format!("cannot run {}: {e}", ctx.exe.display())),
    };
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    match out.status.code() {
        Some(0) => Ended::Ok(stdout),
        Some(130) => Ended::Interrupted("interrupted".into()),
        None => Ended::Interrupted(format!("stopped: {}", out.status)),
        Some(code) => Ended::Failed(error_text(&String::from_utf8_lossy(&out.stderr), code)),
    }
}

/// The child's error: its last `error: …` line, else the end of its stderr.
fn error_text(stderr: &str, code: i32) -> String {
    if let Some(line) = stderr
        .lines()
        .rev()
        .find_map(|l| l.trim().strip_prefix("error: "))
    {
        return line.trim().to_string();
    }
    let lines: Vec<&str> = stderr
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    if lines.is_empty() {
        return format!("exited with status {code}");
    }
    let text = lines[lines.len().saturating_sub(4)..].join(" | ");
    let short: String = text.chars().take(500).collect();
    format!("exited with status {code}: {short}")
}

/// The SHA-256 of an input file, or why it cannot be read.
fn hash_input(p: &Path) -> (InputHash, Option<String>) {
    let path = p.display().to_string();
    match diffsvg::image_io::read_bounded(p, diffsvg::limits::MAX_FILE_BYTES) {
        Ok(bytes) => (
            InputHash {
                path,
                sha256: Some(sha256(&bytes)),
            },
            None,
        ),
        Err(e) => (
            InputHash {
                path: path.clone(),
                sha256: None,
            },
            Some(format!("cannot read: {e}")),
        ),
    }
}

/// Lower-case hex SHA-256.
pub fn sha256(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Every file under the job folder (sorted, `/`-separated), except the manifest, the
/// result and temporary files.
fn list_outputs(dir: &Path) -> Vec<OutputFile> {
    let mut files = Vec::new();
    walk(dir, "", &mut files);
    files.sort();
    files
        .into_iter()
        .filter_map(|rel| {
            let bytes = std::fs::read(dir.join(&rel)).ok()?;
            Some(OutputFile {
                size: bytes.len() as u64,
                sha256: sha256(&bytes),
                path: rel,
            })
        })
        .collect()
}

fn walk(dir: &Path, prefix: &str, out: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || (prefix.is_empty() && (name == MANIFEST || name == RESULT)) {
            continue;
        }
        let rel = format!("{prefix}{name}");
        match e.file_type() {
            Ok(t) if t.is_dir() => walk(&e.path(), &format!("{rel}/"), out),
            Ok(t) if t.is_file() => out.push(rel),
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_text_prefers_the_error_line() {
        assert_eq!(
            error_text("warning: x\nerror: a.svg: malformed\n", 2),
            "a.svg: malformed"
        );
        assert_eq!(error_text("", 3), "exited with status 3");
        assert!(error_text("thread 'main' panicked\nboom\n", 101).contains("boom"));
    }

    #[test]
    fn manifest_paths_stay_inside() {
        assert!(safe_relative("a/b.png"));
        assert!(!safe_relative("../b.png"));
        assert!(!safe_relative("/etc/passwd"));
    }
}
