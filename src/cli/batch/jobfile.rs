//! The job file of `diffsvg batch`: reading (TOML or JSON), glob expansion, the argument
//! list of every job, and validation of all of them before anything runs.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};
use clap::Parser as _;
use serde::Deserialize;
use serde_json::{Map, Value};

/// The subcommands a job may run.
pub const KINDS: [&str; 4] = ["fit", "vectorize", "digits", "render"];

/// Keys a job table may not set: batch sets them itself.
const SET_BY_BATCH: [&str; 9] = [
    "output", "o", "json", "quiet", "q", "help", "h", "version", "V",
];

/// Options whose values are paths, resolved against the job file's folder (a job runs in
/// its own output folder): the fonts of `<text>`.
const PATH_OPTIONS: [&str; 3] = ["font", "font_dir", "font-dir"];

/// The file as written.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct RawFile {
    output: Option<PathBuf>,
    #[serde(default, alias = "jobs")]
    job: Vec<Map<String, Value>>,
}

/// A job file, read and expanded.
#[derive(Debug)]
pub struct JobFile {
    /// The job file's path, as given.
    pub path: PathBuf,
    /// The root output folder (from the file, relative to its folder), if it names one.
    pub output: Option<PathBuf>,
    /// The jobs after glob expansion, in file order.
    pub jobs: Vec<Job>,
}

/// One job after glob expansion.
#[derive(Debug, Clone)]
pub struct Job {
    /// Position after expansion (0-based); shards pick by it.
    pub index: usize,
    /// 1-based number of the `[[job]]` table it comes from.
    pub table: usize,
    /// Unique name: the job's folder under the output root.
    pub name: String,
    /// The subcommand: one of [`KINDS`].
    pub kind: String,
    /// Input files (absolute), hashed into the manifest.
    pub inputs: Vec<PathBuf>,
    /// Input files as the job file gives them (relative to its folder when possible).
    pub shown_inputs: Vec<String>,
    /// The child's arguments, subcommand first (no program name).
    pub args: Vec<String>,
    /// The main output file, relative to the job folder (`None` for digits: a folder).
    pub output: Option<String>,
    /// A failure known before running (a glob that matches nothing).
    pub error: Option<String>,
}

/// Reads, expands and validates a job file. Errors name the file (and the job).
pub fn load(path: &Path) -> Result<JobFile> {
    let raw = read_raw(path)?;
    if raw.job.is_empty() {
        bail!("{}: no jobs (add [[job]] tables)", path.display());
    }
    let base = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut jobs = Vec::new();
    for (i, table) in raw.job.iter().enumerate() {
        let label = job_label(i + 1, table);
        let expanded = expand(i + 1, table, &base)
            .map_err(|e| anyhow!("{}: {label}: {e:#}", path.display()))?;
        jobs.extend(expanded);
    }
    for (i, j) in jobs.iter_mut().enumerate() {
        j.index = i;
    }
    check_unique(&jobs).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    for j in &jobs {
        validate(j)
            .map_err(|e| anyhow!("{}: job {} ({}): {e}", path.display(), j.table, j.name))?;
    }
    Ok(JobFile {
        path: path.to_path_buf(),
        output: raw.output.map(|o| base.join(o)),
        jobs,
    })
}

/// Parses the file as TOML or JSON, chosen by its extension.
fn read_raw(path: &Path) -> Result<RawFile> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    if !matches!(ext.as_deref(), Some("toml" | "json")) {
        bail!(
            "{}: a job file must be a .toml or .json file",
            path.display()
        );
    }
    let bytes = diffsvg::image_io::read_bounded(path, diffsvg::limits::MAX_FILE_BYTES)
        .map_err(|e| anyhow!("cannot read the job file: {e}"))?;
    let text = String::from_utf8(bytes)
        .map_err(|_| anyhow!("{}: the job file is not UTF-8 text", path.display()))?;
    if ext.as_deref() == Some("json") {
        serde_json::from_str(&text)
            .map_err(|e| anyhow!("{}: not a valid job file: {e}", path.display()))
    } else {
        toml::from_str(&text).map_err(|e| anyhow!("{}: {}", path.display(), toml_error(&e, &text)))
    }
}

/// A TOML error on one line: `line L, column C: message`.
fn toml_error(e: &toml::de::Error, text: &str) -> String {
    let msg = e.message().trim().replace('\n', " ");
    match e.span() {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            format!("not a valid job file: line {line}, column {col}: {msg}")
        }
        None => format!("not a valid job file: {msg}"),
    }
}

/// `job 3 (name)` for messages: the explicit name, else the kind, else `?`.
fn job_label(table: usize, t: &Map<String, Value>) -> String {
    let name = t
        .get("name")
        .or_else(|| t.get("kind"))
        .and_then(Value::as_str)
        .unwrap_or("?");
    format!("job {table} ({name})")
}

/// What each kind takes as inputs and writes.
struct KindSpec {
    /// Keys holding input paths, in positional order; the glob key may hold a pattern.
    input_keys: &'static [&'static str],
    /// The one key that may be a glob.
    glob_key: Option<&'static str>,
    /// Input keys that may be left out.
    optional: &'static [&'static str],
    /// Inputs are positional arguments (else `--key=path` flags).
    positional: bool,
    /// Extension of the main output (`None`: the output is the job folder).
    out_ext: Option<&'static str>,
    /// The subcommand has `--json`.
    json: bool,
}

fn spec(kind: &str) -> Option<KindSpec> {
    Some(match kind {
        "render" => KindSpec {
            input_keys: &["input"],
            glob_key: Some("input"),
            optional: &[],
            positional: true,
            out_ext: Some("png"),
            json: false,
        },
        "vectorize" => KindSpec {
            input_keys: &["input"],
            glob_key: Some("input"),
            optional: &[],
            positional: true,
            out_ext: Some("svg"),
            json: true,
        },
        "fit" => KindSpec {
            input_keys: &["init", "target"],
            glob_key: Some("target"),
            optional: &[],
            positional: true,
            out_ext: Some("svg"),
            json: true,
        },
        "digits" => KindSpec {
            input_keys: &["images", "labels"],
            glob_key: None,
            optional: &["labels"],
            positional: false,
            out_ext: None,
            json: true,
        },
        _ => return None,
    })
}

/// Expands one `[[job]]` table into jobs (one per glob match).
fn expand(table: usize, t: &Map<String, Value>, base: &Path) -> Result<Vec<Job>> {
    let kind = match t.get("kind") {
        None => bail!("no `kind` (expected one of {})", KINDS.join(", ")),
        Some(Value::String(k)) => k.clone(),
        Some(v) => bail!("`kind` must be a string, not {v}"),
    };
    let spec = spec(&kind).ok_or_else(|| {
        anyhow!(
            "unknown kind {kind:?} (expected one of {})",
            KINDS.join(", ")
        )
    })?;
    let name = match t.get("name") {
        None => kind.clone(),
        Some(Value::String(n)) => {
            check_name(n)?;
            n.clone()
        }
        Some(v) => bail!("`name` must be a string, not {v}"),
    };
    let inputs = input_values(t, &spec, base)?;
    let flags = flags(t, &spec, base)?;
    let proto = Job {
        index: 0,
        table,
        name,
        kind,
        inputs: Vec::new(),
        shown_inputs: Vec::new(),
        args: Vec::new(),
        output: None,
        error: None,
    };
    let glob = spec
        .glob_key
        .and_then(|k| inputs.iter().find(|(key, _)| *key == k))
        .filter(|(_, v)| is_glob(v) && !base.join(v).exists())
        .map(|(k, v)| (*k, v.clone()));
    let Some((gkey, pattern)) = glob else {
        return Ok(vec![build(proto, &spec, &inputs, &flags, base)]);
    };
    let matches = glob_matches(base, &pattern)?;
    if matches.is_empty() {
        let mut job = build(proto, &spec, &inputs, &flags, base);
        job.error = Some(format!("{pattern}: no file matches this pattern"));
        job.inputs.clear();
        return Ok(vec![job]);
    }
    Ok(matches
        .into_iter()
        .map(|m| {
            let shown = shown(base, &m);
            let with: Vec<(&str, String)> = inputs
                .iter()
                .map(|(k, v)| (*k, if *k == gkey { shown.clone() } else { v.clone() }))
                .collect();
            let mut job = proto.clone();
            job.name = format!("{}-{}", proto.name, sanitize(&stem(&m)));
            build(job, &spec, &with, &flags, base)
        })
        .collect())
}

/// The input keys' values, in positional order; checks that required ones are present and
/// that only the glob key holds a pattern (a value naming an existing file is a plain path,
/// brackets and all).
fn input_values(
    t: &Map<String, Value>,
    spec: &KindSpec,
    base: &Path,
) -> Result<Vec<(&'static str, String)>> {
    let mut out = Vec::new();
    for &key in spec.input_keys {
        match t.get(key) {
            None if spec.optional.contains(&key) => {}
            None => bail!("no `{key}` (an input file{})", glob_note(spec, key)),
            Some(Value::String(v)) if v.is_empty() => bail!("`{key}` is empty"),
            Some(Value::String(v)) => {
                if is_glob(v) && spec.glob_key != Some(key) && !base.join(v).exists() {
                    bail!("`{key}` must be a plain path, not a glob ({v:?})");
                }
                out.push((key, v.clone()));
            }
            Some(v) => bail!("`{key}` must be a string (a path), not {v}"),
        }
    }
    Ok(out)
}

fn glob_note(spec: &KindSpec, key: &str) -> &'static str {
    if spec.glob_key == Some(key) {
        ": a path or a glob"
    } else {
        ": a path"
    }
}

/// Files matching `pattern` (relative to `base`), sorted.
fn glob_matches(base: &Path, pattern: &str) -> Result<Vec<PathBuf>> {
    let full = base.join(pattern);
    let full = full
        .to_str()
        .ok_or_else(|| anyhow!("{pattern}: the path is not valid UTF-8"))?;
    let paths = glob::glob(full).map_err(|e| anyhow!("{pattern}: not a valid glob: {e}"))?;
    let mut v: Vec<PathBuf> = paths
        .filter_map(|p| p.ok())
        .filter(|p| p.is_file())
        .collect();
    v.sort();
    Ok(v)
}

/// Whether a value has glob characters. It is taken as a pattern only when no file of
/// that exact name exists (`a [1].svg` is a plain path when it is there); to match a
/// literal `[`, `*` or `?` in a pattern, write `[[]`, `[*]` or `[?]`.
fn is_glob(s: &str) -> bool {
    s.contains(['*', '?', '['])
}

/// A path for messages and summaries: relative to the job file's folder when it is inside.
fn shown(base: &Path, p: &Path) -> String {
    let rel = p.strip_prefix(base).unwrap_or(p);
    rel.display().to_string()
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "input".into())
}

/// Longest name [`sanitize`] returns, in bytes: a job's folder name, under the usual
/// 255-byte limit of a file name with room for a prefix.
const MAX_NAME_BYTES: usize = 200;

/// A name safe as a folder name and in a link: keeps ASCII `[A-Za-z0-9._-]` and every
/// other non-ASCII character (so `日本` and `中国` stay apart), replaces with `_` the
/// rest of ASCII (path separators, spaces, punctuation), control characters, other
/// whitespace and invisible direction marks, and a leading `.` or `-`; cuts the name to
/// [`MAX_NAME_BYTES`] bytes on a character boundary.
fn sanitize(s: &str) -> String {
    let keep = |c: char| {
        if c.is_ascii() {
            c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-')
        } else {
            !(c.is_control()
                || c.is_whitespace()
                || matches!(c, '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}' | '\u{feff}'))
        }
    };
    let mut out = String::new();
    for c in s.chars() {
        let c = if keep(c) { c } else { '_' };
        if out.len() + c.len_utf8() > MAX_NAME_BYTES {
            break;
        }
        out.push(c);
    }
    if out.is_empty() {
        out.push('_');
    }
    if out.starts_with(['.', '-']) {
        out.replace_range(0..1, "_");
    }
    out
}

/// A job name is a folder name: letters, digits, `.`, `_`, `-`, not starting with `.`/`-`.
fn check_name(n: &str) -> Result<()> {
    if n.is_empty() || sanitize(n) != n {
        bail!(
            "name {n:?} must be made of letters, digits, '.', '_' and '-', and not start with '.' or '-' (it names the job's folder)"
        );
    }
    if n.starts_with("summary.") || n.starts_with("report.") {
        bail!("name {n:?} is taken by the batch's summary files");
    }
    Ok(())
}

/// Turns every non-reserved key into flags: `key = v` → `--key=v` (underscores become
/// dashes), `true` → `--key`, `false` → nothing, an array → the flag repeated.
fn flags(t: &Map<String, Value>, spec: &KindSpec, base: &Path) -> Result<Vec<String>> {
    let mut out = Vec::new();
    for (key, value) in t {
        if key == "kind" || key == "name" || spec.input_keys.contains(&key.as_str()) {
            continue;
        }
        if SET_BY_BATCH.contains(&key.as_str()) {
            bail!("option `{key}` is set by batch (each job writes into <output>/<job name>/)");
        }
        if key.is_empty()
            || !key
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            bail!("option {key:?} is not a flag name");
        }
        let flag = format!("--{}", key.replace('_', "-"));
        let text = |v: &Value| -> Result<String> {
            let s = scalar(key, v)?;
            Ok(if PATH_OPTIONS.contains(&key.as_str()) {
                let p = base.join(&s);
                std::path::absolute(&p).unwrap_or(p).display().to_string()
            } else {
                s
            })
        };
        match value {
            Value::Bool(true) => out.push(flag),
            Value::Bool(false) => {}
            Value::Array(items) => {
                for item in items {
                    out.push(format!("{flag}={}", text(item)?));
                }
            }
            v => out.push(format!("{flag}={}", text(v)?)),
        }
    }
    Ok(out)
}

/// A number or a string as flag text.
fn scalar(key: &str, v: &Value) -> Result<String> {
    match v {
        Value::String(s) => Ok(s.clone()),
        Value::Number(n) => Ok(n.to_string()),
        Value::Null => bail!("option `{key}` has no value (null, NaN or infinity)"),
        Value::Bool(_) => bail!("option `{key}`: true/false only as a whole value, not in a list"),
        Value::Array(_) | Value::Object(_) => {
            bail!("option `{key}` must be a number, a string, true/false or a list of them")
        }
    }
}

/// Fills in a job's inputs, argument list and output name.
fn build(
    mut job: Job,
    spec: &KindSpec,
    inputs: &[(&str, String)],
    flags: &[String],
    base: &Path,
) -> Job {
    let resolved: Vec<PathBuf> = inputs
        .iter()
        .map(|(_, v)| {
            let p = base.join(v);
            std::path::absolute(&p).unwrap_or(p)
        })
        .collect();
    job.shown_inputs = inputs.iter().map(|(_, v)| v.clone()).collect();
    let mut args = vec![job.kind.clone()];
    args.extend(flags.iter().cloned());
    if !spec.positional {
        for ((key, _), p) in inputs.iter().zip(&resolved) {
            args.push(format!("--{key}={}", p.display()));
        }
    }
    let out = spec.out_ext.map(|ext| {
        let last = resolved
            .last()
            .map_or_else(|| "out".into(), |p| sanitize(&stem(p)));
        format!("{last}.{ext}")
    });
    args.push("-o".into());
    args.push(out.clone().unwrap_or_else(|| ".".into()));
    if spec.json {
        args.push("--json".into());
    }
    if spec.positional {
        args.push("--".into());
        args.extend(resolved.iter().map(|p| p.display().to_string()));
    }
    job.inputs = resolved;
    job.args = args;
    job.output = out;
    job
}

/// Job names must be unique after expansion: they name folders.
fn check_unique(jobs: &[Job]) -> Result<()> {
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for j in jobs {
        if let Some(first) = seen.insert(&j.name, j.table) {
            bail!(
                "job {} ({}): the name is also used by job {first}; give the jobs different `name`s",
                j.table,
                j.name
            );
        }
    }
    Ok(())
}

/// Parses the job's argument list with the real command line, so that an unknown option
/// or a bad value is reported before anything runs.
fn validate(job: &Job) -> Result<()> {
    let argv = std::iter::once("diffsvg".to_string()).chain(job.args.iter().cloned());
    match super::super::Cli::try_parse_from(argv) {
        Ok(_) => Ok(()),
        Err(e) => bail!("{}", super::super::one_line(&e)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sanitize_keeps_safe_names() {
        assert_eq!(sanitize("01-curves"), "01-curves");
        assert_eq!(sanitize("a b/c"), "a_b_c");
        assert_eq!(sanitize(".hidden"), "_hidden");
        assert_eq!(sanitize("-x"), "_x");
    }

    /// issue 13, case 10: non-ASCII stems collapsed to underscores and collided.
    #[test]
    fn sanitize_keeps_unicode_letters() {
        assert_eq!(sanitize("日本"), "日本");
        assert_eq!(sanitize("中国"), "中国");
        assert_eq!(sanitize("café नमस्ते"), "café_नमस्ते");
        assert_eq!(sanitize("a\u{202e}b\u{3000}c\u{7f}d\\e"), "a_b_c_d_e");
        let long = sanitize(&"字".repeat(100));
        assert!(long.len() <= MAX_NAME_BYTES && long.chars().all(|c| c == '字'));
        assert!(check_name("日本").is_ok());
    }

    #[test]
    fn flags_follow_the_documented_mapping() {
        let t: Map<String, Value> = serde_json::from_str(
            r#"{"kind": "fit", "iters": 5, "until_psnr": 30.5, "compare": true,
                "quiet_x": false, "freeze": ["points", "colors"], "loss": "l1"}"#,
        )
        .unwrap();
        let f = flags(&t, &spec("fit").unwrap(), Path::new("/jobs")).unwrap();
        assert_eq!(
            f,
            [
                "--compare",
                "--freeze=points",
                "--freeze=colors",
                "--iters=5",
                "--loss=l1",
                "--until-psnr=30.5"
            ]
        );
    }

    #[test]
    fn font_paths_are_relative_to_the_job_file() {
        let t: Map<String, Value> = serde_json::from_str(
            r#"{"kind": "render", "font": ["a.ttf", "/abs/b.otf"], "font_dir": "fonts",
                "font_fallback": true}"#,
        )
        .unwrap();
        let f = flags(&t, &spec("render").unwrap(), Path::new("/jobs")).unwrap();
        assert_eq!(
            f,
            [
                "--font=/jobs/a.ttf",
                "--font=/abs/b.otf",
                "--font-dir=/jobs/fonts",
                "--font-fallback"
            ]
        );
    }

    #[test]
    fn toml_errors_fit_on_one_line() {
        let text = "output = \"x\"\n[[job]\nkind = 1\n";
        let e = toml::from_str::<RawFile>(text).unwrap_err();
        let m = toml_error(&e, text);
        assert!(m.contains("line 2"), "{m}");
        assert!(!m.contains('\n'), "{m}");
    }
}
