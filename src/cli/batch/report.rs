//! The batch's summaries: `summary.csv`, `summary.json` and `report.html`.

use std::path::{Path, PathBuf};

use anyhow::Result;
use serde_json::json;

use super::Shard;
use super::runner::{Outcome, Status};
use diffsvg::image_io::write_atomic;
use diffsvg::scene::escape as esc;

/// Counts of a batch's outcomes.
#[derive(Debug, Default, Clone, Copy)]
pub struct Counts {
    /// Ran and succeeded.
    pub ok: usize,
    /// Complete from an earlier run.
    pub skipped: usize,
    /// Failed (now or recorded).
    pub failed: usize,
}

impl Counts {
    /// Counts outcomes by status.
    pub fn of(outcomes: &[Outcome]) -> Self {
        let mut c = Counts::default();
        for o in outcomes {
            match o.status {
                Status::Ok => c.ok += 1,
                Status::Skipped => c.skipped += 1,
                Status::Failed => c.failed += 1,
            }
        }
        c
    }
}

/// The summary's file name: `summary.csv`, or `summary.shard-K-of-N.csv` for a shard.
fn file_name(stem: &str, ext: &str, shard: Option<Shard>) -> String {
    match shard {
        Some(s) => format!("{stem}.shard-{}-of-{}.{ext}", s.k, s.n),
        None => format!("{stem}.{ext}"),
    }
}

/// Writes the three summaries into `root`; returns the path of `summary.json`.
pub fn write(
    root: &Path,
    job_file: &Path,
    shard: Option<Shard>,
    outcomes: &[Outcome],
) -> Result<PathBuf> {
    write_atomic(
        &root.join(file_name("summary", "csv", shard)),
        csv(outcomes).as_bytes(),
    )?;
    let json_path = root.join(file_name("summary", "json", shard));
    let c = Counts::of(outcomes);
    let doc = json!({
        "diffsvg": env!("CARGO_PKG_VERSION"),
        "job_file": job_file.display().to_string(),
        "shard": shard.map(|s| format!("{}/{}", s.k, s.n)),
        "counts": {"ok": c.ok, "skipped": c.skipped, "failed": c.failed},
        "jobs": outcomes,
    });
    write_atomic(&json_path, serde_json::to_string_pretty(&doc)?.as_bytes())?;
    write_atomic(
        &root.join(file_name("report", "html", shard)),
        html(job_file, outcomes).as_bytes(),
    )?;
    Ok(json_path)
}

fn status(o: &Outcome) -> &'static str {
    match o.status {
        Status::Ok => "ok",
        Status::Skipped => "skipped",
        Status::Failed => "failed",
    }
}

/// `name,kind,status,inputs,psnr,paths,seconds,output,error`, inputs joined by `;`.
pub fn csv(outcomes: &[Outcome]) -> String {
    let mut s = String::from("name,kind,status,inputs,psnr,paths,seconds,output,error\n");
    for o in outcomes {
        let row = [
            o.name.clone(),
            o.kind.clone(),
            status(o).to_string(),
            o.inputs.join(";"),
            o.psnr
                .filter(|p| p.is_finite())
                .map(|p| format!("{p:.4}"))
                .unwrap_or_default(),
            o.paths.map(|p| p.to_string()).unwrap_or_default(),
            format!("{:.3}", o.seconds),
            o.output.clone().unwrap_or_default(),
            o.error.clone().unwrap_or_default(),
        ];
        let fields: Vec<String> = row.iter().map(|f| csv_field(f)).collect();
        s += &fields.join(",");
        s.push('\n');
    }
    s
}

/// Quotes a CSV field when it holds a comma, a quote or a line break.
fn csv_field(f: &str) -> String {
    if f.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", f.replace('"', "\"\""))
    } else {
        f.to_string()
    }
}

/// A page with one table row per job.
fn html(job_file: &Path, outcomes: &[Outcome]) -> String {
    let c = Counts::of(outcomes);
    let mut s = format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>diffsvg batch: {title}</title>\n\
         <style>body{{font-family:sans-serif}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #ccc;padding:4px 8px;text-align:left;vertical-align:top}}\
         .failed{{background:#fdd}}.skipped{{color:#666}}img{{background:#fff}}</style></head><body>\n\
         <h1>{title}</h1>\n<p>{} jobs: {} ok, {} skipped, {} failed</p>\n<table>\n\
         <tr><th></th><th>name</th><th>kind</th><th>status</th><th>PSNR (dB)</th><th>paths</th>\
         <th>time (s)</th><th>output</th><th>error</th></tr>\n",
        outcomes.len(),
        c.ok,
        c.skipped,
        c.failed,
        title = esc(&job_file.display().to_string()),
    );
    for o in outcomes {
        s += &row(o);
    }
    s += "</table>\n</body></html>\n";
    s
}

fn row(o: &Outcome) -> String {
    let img = o
        .thumbnail
        .as_ref()
        .map(|t| format!("<img src=\"{}\" alt=\"\">", esc(t)))
        .unwrap_or_default();
    let output = o
        .output
        .as_ref()
        .map(|p| format!("<a href=\"{0}\">{0}</a>", esc(p)))
        .unwrap_or_default();
    format!(
        "<tr class=\"{st}\"><td>{img}</td><td>{}</td><td>{}</td><td>{st}{}</td><td>{}</td><td>{}</td>\
         <td>{:.2}</td><td>{output}</td><td>{}</td></tr>\n",
        esc(&o.name),
        esc(&o.kind),
        if o.cached && o.status == Status::Failed {
            " (recorded)"
        } else {
            ""
        },
        o.psnr
            .filter(|p| p.is_finite())
            .map(|p| format!("{p:.2}"))
            .unwrap_or_default(),
        o.paths.map(|p| p.to_string()).unwrap_or_default(),
        o.seconds,
        esc(o.error.as_deref().unwrap_or("")),
        st = status(o),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_are_quoted_and_escaped() {
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"x\""), "\"say \"\"x\"\"\"");
        assert_eq!(csv_field("plain"), "plain");
        assert_eq!(esc("<a href='x'>&"), "&lt;a href=&#39;x&#39;&gt;&amp;");
    }
}
