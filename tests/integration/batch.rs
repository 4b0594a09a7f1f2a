//! `diffsvg batch`: mixed good and bad jobs, `--resume`, shards, bad job files.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::SystemTime;

use serde_json::Value;

use super::common::{assert_fails, diffsvg, root, s, scratch, write};

/// The bundled samples folder, `/`-separated for a TOML literal string.
fn samples_dir() -> String {
    s(&root().join("svg-samples")).replace('\\', "/")
}

/// The JSON lines of a batch run: job lines by name, and the final `done` line.
fn lines(out: &Output) -> (BTreeMap<String, Value>, Value) {
    let text = String::from_utf8_lossy(&out.stdout);
    let mut jobs = BTreeMap::new();
    let mut done = Value::Null;
    for l in text.lines() {
        let v: Value = serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l:?}"));
        if v["done"] == true {
            done = v;
        } else {
            jobs.insert(v["name"].as_str().unwrap().to_string(), v);
        }
    }
    (jobs, done)
}

/// Modification times of every file under `dir`.
fn mtimes(dir: &Path) -> BTreeMap<PathBuf, SystemTime> {
    let mut m = BTreeMap::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            m.extend(mtimes(&p));
        } else {
            m.insert(p.clone(), e.metadata().unwrap().modified().unwrap());
        }
    }
    m
}

/// Two 28×28 "digits" (vertical bars) as an unsigned-byte IDX file.
fn write_bars(path: &Path) {
    let mut b = vec![0u8, 0, 8, 3];
    for d in [2u32, 28, 28] {
        b.extend_from_slice(&d.to_be_bytes());
    }
    for k in 0..2 {
        for y in 0..28 {
            for x in 0..28 {
                let ink = (5..23).contains(&y) && (x == 13 + k || x == 14 + k);
                b.push(if ink { 255 } else { 0 });
            }
        }
    }
    std::fs::write(path, b).unwrap();
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

const GOOD_AND_BAD: &str = r#"
output = "out"

[[job]]
kind = "render"
name = "pics"
input = 'SAMPLES/0[12]-*.svg'
width = 64

[[job]]
kind = "vectorize"
input = 'SAMPLES/01-curves.svg'
paths = 4
iters = 30
width = 48

[[job]]
kind = "fit"
init = 'SAMPLES/01-curves.svg'
target = 'SAMPLES/05-translucent-overlap.svg'
iters = 15
freeze = ["stops"]

[[job]]
kind = "digits"
images = "bars.idx"
indices = "0..2"

[[job]]
kind = "render"
name = "missing"
input = "missing.svg"

[[job]]
kind = "render"
name = "malformed"
input = "bad.svg"
"#;

#[test]
fn good_jobs_finish_bad_ones_are_reported_and_resume_redoes_nothing() {
    let dir = scratch("batch_mixed");
    write(
        &dir,
        "bad.svg",
        "<svg xmlns='http://www.w3.org/2000/svg'><rect",
    );
    write_bars(&dir.join("bars.idx"));
    let jobs = write(
        &dir,
        "jobs.toml",
        &GOOD_AND_BAD.replace("SAMPLES", &samples_dir()),
    );
    let out = dir.join("out");

    let r = diffsvg(&["batch", s(&jobs)]);
    assert_eq!(r.status.code(), Some(1), "{}", stderr(&r));
    let (lines1, done) = lines(&r);
    let names: Vec<&str> = lines1.keys().map(String::as_str).collect();
    assert_eq!(
        names,
        [
            "digits",
            "fit",
            "malformed",
            "missing",
            "pics-01-curves",
            "pics-02-strokes",
            "vectorize"
        ]
    );
    assert_eq!(
        (done["ok"].as_u64(), done["failed"].as_u64()),
        (Some(5), Some(2))
    );

    // Good outputs are complete.
    let good = [
        ("pics-01-curves", "01-curves.png"),
        ("pics-02-strokes", "02-strokes.png"),
        ("vectorize", "01-curves.svg"),
        ("fit", "05-translucent-overlap.svg"),
        ("digits", "contact.png"),
    ];
    for (name, file) in good {
        let line = &lines1[name];
        assert_eq!(line["status"], "ok", "{line}");
        assert_eq!(line["cached"], false);
        if name != "digits" {
            assert_eq!(line["output"], format!("{name}/{file}"));
        }
        for f in [file, "thumb.png", "manifest.json", "result.json"] {
            assert!(out.join(name).join(f).is_file(), "{name}/{f} missing");
        }
        let thumb = diffsvg::Image::load(out.join(name).join("thumb.png")).unwrap();
        assert!(thumb.width.max(thumb.height) <= 128);
        assert!(line["paths"].as_u64().unwrap() > 0, "{line}");
        assert!(line["seconds"].as_f64().unwrap() > 0.0);
    }
    let png = diffsvg::Image::load(out.join("pics-01-curves/01-curves.png")).unwrap();
    assert_eq!(png.width, 64);
    assert_eq!(lines1["vectorize"]["paths"], 4);
    assert!(lines1["fit"]["psnr"].as_f64().unwrap() > 5.0);
    assert_eq!(lines1["digits"]["output"], "digits/");
    assert!(out.join("digits/digit-00001.svg").is_file());
    assert!(lines1["digits"]["psnr"].as_f64().unwrap() > 10.0);
    diffsvg::Scene::load(
        out.join("vectorize/01-curves.svg"),
        diffsvg::Sizing::Natural,
    )
    .unwrap();

    // Bad ones are reported with errors that name the file.
    for (name, file, what) in [
        ("missing", "missing.svg", "cannot read"),
        ("malformed", "bad.svg", "malformed"),
    ] {
        let line = &lines1[name];
        assert_eq!(line["status"], "failed", "{line}");
        let err = line["error"].as_str().unwrap();
        assert!(err.contains(file) && err.contains(what), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(line["output"].is_null());
    }

    // The summaries list every job.
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(
        rows[0],
        "name,kind,status,inputs,psnr,paths,seconds,output,error"
    );
    assert_eq!(rows.len(), 8, "{csv}");
    for name in &names {
        assert!(
            rows.iter().any(|r| r.starts_with(&format!("{name},"))),
            "{name}: {csv}"
        );
    }
    assert!(csv.contains("malformed,render,failed,bad.svg"), "{csv}");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["jobs"].as_array().unwrap().len(), 7);
    assert_eq!(summary["counts"]["failed"], 2);
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        html.contains("<img src=\"pics-01-curves/thumb.png\""),
        "{html}"
    );
    assert!(html.contains("bad.svg"));

    // --resume runs nothing: same modification times, every job cached.
    let before = mtimes(&out);
    std::thread::sleep(std::time::Duration::from_millis(1100));
    let r = diffsvg(&["batch", s(&jobs), "--resume"]);
    assert_eq!(
        r.status.code(),
        Some(1),
        "failed jobs still fail: {}",
        stderr(&r)
    );
    let (lines2, done) = lines(&r);
    assert_eq!(lines2.len(), 7);
    assert_eq!(
        (done["skipped"].as_u64(), done["failed"].as_u64()),
        (Some(5), Some(2))
    );
    for (name, line) in &lines2 {
        assert_eq!(line["cached"], true, "{line}");
        let expected = if lines1[name]["status"] == "ok" {
            "skipped"
        } else {
            "failed"
        };
        assert_eq!(line["status"], expected, "{line}");
        assert_eq!(
            line["psnr"], lines1[name]["psnr"],
            "figures come from the manifest"
        );
    }
    let after = mtimes(&out);
    for (p, t) in &before {
        let name = p.file_name().unwrap().to_string_lossy();
        if !name.starts_with("summary") && !name.starts_with("report") {
            assert_eq!(after.get(p), Some(t), "{} was rewritten", p.display());
        }
    }
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert!(csv.contains("vectorize,vectorize,skipped,"), "{csv}");

    // --retry-failed runs only the failed jobs again.
    let r = diffsvg(&["batch", s(&jobs), "--resume", "--retry-failed", "--quiet"]);
    assert_eq!(r.status.code(), Some(1));
    assert!(r.stdout.is_empty(), "--quiet prints nothing");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    for j in summary["jobs"].as_array().unwrap() {
        assert_eq!(j["cached"], j["status"] == "skipped", "{j}");
    }
}

const SHARDED: &str = r#"
[[job]]
kind = "render"
input = 'SAMPLES/0[1-5]-*.svg'
width = 48

[[job]]
kind = "vectorize"
name = "vec"
input = 'SAMPLES/0[12]-*.svg'
paths = 3
iters = 25
width = 40

[[job]]
kind = "fit"
init = 'SAMPLES/01-curves.svg'
target = 'SAMPLES/06-evenodd-star.svg'
iters = 10
"#;

#[test]
fn shards_split_the_jobs_and_match_the_unsharded_run() {
    let dir = scratch("batch_shards");
    let jobs = write(
        &dir,
        "jobs.toml",
        &SHARDED.replace("SAMPLES", &samples_dir()),
    );
    let full = dir.join("full");
    let sharded = dir.join("sharded");

    let r = diffsvg(&["batch", s(&jobs), "-o", s(&full), "--jobs", "2"]);
    assert!(r.status.success(), "{}", stderr(&r));
    let (all, _) = lines(&r);
    assert_eq!(all.len(), 8);
    assert!(all.values().all(|l| l["status"] == "ok"));

    let mut union = BTreeSet::new();
    for k in 0..2 {
        let shard = format!("{k}/2");
        let r = diffsvg(&["batch", s(&jobs), "-o", s(&sharded), "--shard", &shard]);
        assert!(r.status.success(), "{}", stderr(&r));
        let (ran, done) = lines(&r);
        assert_eq!(done["jobs"].as_u64(), Some(ran.len() as u64));
        for (name, line) in ran {
            assert_eq!(line["index"].as_u64().unwrap() % 2, k, "{line}");
            assert!(union.insert(name.clone()), "{name} ran in two shards");
        }
        let csv = std::fs::read_to_string(sharded.join(format!("summary.shard-{k}-of-2.csv")));
        assert!(csv.is_ok(), "a shard writes its own summary");
        assert!(
            sharded
                .join(format!("report.shard-{k}-of-2.html"))
                .is_file()
        );
    }
    assert!(!sharded.join("summary.csv").exists());
    assert_eq!(union, all.keys().cloned().collect::<BTreeSet<_>>());

    for (name, line) in &all {
        let out = line["output"].as_str().unwrap();
        for file in [out.to_string(), format!("{name}/thumb.png")] {
            let a = std::fs::read(full.join(&file)).unwrap();
            let b = std::fs::read(sharded.join(&file)).unwrap();
            assert!(
                a == b,
                "{file} differs between the sharded and unsharded runs"
            );
        }
    }

    // The merge step: --resume over the shards' folder runs nothing, writes the summary.
    let r = diffsvg(&["batch", s(&jobs), "-o", s(&sharded), "--resume"]);
    assert!(r.status.success(), "{}", stderr(&r));
    let (merged, done) = lines(&r);
    assert_eq!(done["skipped"].as_u64(), Some(8));
    assert!(merged.values().all(|l| l["status"] == "skipped"));
    let csv = std::fs::read_to_string(sharded.join("summary.csv")).unwrap();
    assert_eq!(csv.lines().count(), 9, "{csv}");
}

#[test]
fn bad_job_files_fail_before_running_anything() {
    let dir = scratch("batch_bad");
    let out = dir.join("out");
    let good = format!(
        "[[job]]\nkind = \"render\"\ninput = '{}/01-curves.svg'\n",
        samples_dir()
    );
    let cases = [
        (
            "malformed.toml",
            "[[job]\nkind = \"render\"\n".to_string(),
            "line 1",
            "",
        ),
        (
            "kind.toml",
            format!("{good}[[job]]\nkind = \"paint\"\nname = \"walls\"\ninput = 'a.svg'\n"),
            "unknown kind",
            "job 2 (walls)",
        ),
        (
            "option.toml",
            format!(
                "{good}[[job]]\nkind = \"render\"\nname = \"shapes\"\ninput = 'a.svg'\nbogus = 3\n"
            ),
            "--bogus",
            "job 2 (shapes)",
        ),
        (
            "value.toml",
            format!("{good}[[job]]\nkind = \"vectorize\"\ninput = 'a.png'\npaths = \"many\"\n"),
            "invalid value",
            "job 2 (vectorize)",
        ),
        (
            "nokind.json",
            r#"{"job": [{"input": "a.svg"}]}"#.to_string(),
            "no `kind`",
            "job 1",
        ),
        (
            "notjson.json",
            "{\"job\": [".to_string(),
            "not a valid job file",
            "",
        ),
        (
            "same.toml",
            format!("{good}{good}"),
            "different `name`s",
            "job 2 (render)",
        ),
    ];
    for (file, text, what, job) in cases {
        let path = write(&dir, file, &text);
        let r = diffsvg(&["batch", s(&path), "-o", s(&out)]);
        assert_fails(&r, file, what, &out);
        assert!(stderr(&r).contains(job), "{} should name {job}", stderr(&r));
        assert!(
            r.stdout.is_empty(),
            "nothing ran: {}",
            String::from_utf8_lossy(&r.stdout)
        );
    }

    let path = write(&dir, "jobs.toml", &good);
    assert_fails(
        &diffsvg(&["batch", s(&dir.join("absent.toml")), "-o", s(&out)]),
        "absent.toml",
        "cannot read",
        &out,
    );
    let r = diffsvg(&["batch", s(&path), "-o", s(&out), "--shard", "2/2"]);
    assert_eq!(r.status.code(), Some(2));
    assert!(stderr(&r).contains("K must be below N"), "{}", stderr(&r));
    assert!(!out.exists());
}
