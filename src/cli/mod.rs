//! The `diffsvg` command line. Every subcommand reports errors as one line naming the
//! file and the problem, and exits with status 2.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod batch;
mod bench;
mod bench_fit;
mod bench_splat;
mod bench_suite;
mod bench_voxel;
mod choices;
mod compare;
mod digits;
mod fit;
mod glyphs;
mod grad;
mod ladder;
mod mesh;
mod ngp;
mod parity;
mod perturb;
mod plot;
mod progress;
mod recon_report;
mod render;
mod splat;
mod util;
mod vectorize;
mod viewed;
mod volume;

/// Differentiable vector rendering: render, compare and fit SVGs.
#[derive(Parser, Debug)]
#[command(name = "diffsvg", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render an SVG to PNG with the analytic-coverage rasterizer.
    Render(render::Args),
    /// Compare diffsvg with resvg over SVG files or folders, per folder pass rates.
    Parity(parity::Args),
    /// Time forward rendering against resvg (medians of several runs).
    Bench(bench::Args),
    /// Print the loss of an SVG's rendering against a target image.
    Loss(grad::LossArgs),
    /// Print the gradient of the loss with respect to every shape parameter.
    Grad(grad::GradArgs),
    /// Refine an SVG's shapes and paints until its rendering matches a target image.
    Fit(fit::Args),
    /// Write a copy of an SVG with control points and colors moved at random.
    Perturb(perturb::Args),
    /// Build an SVG from a picture with as few paths as it needs.
    Vectorize(vectorize::Args),
    /// Fit closed cubic outlines to rendered glyphs with the fewest segments that reach an
    /// IoU goal, beside the glyphs' own segment counts.
    Glyphs(glyphs::Args),
    /// Run a job file of fit, vectorize, digits and render jobs: parallel, resumable, sharded.
    Batch(batch::Args),
    /// Fit strokes to handwritten digits (MNIST IDX files): SVGs, summary.csv, contact.png.
    Digits(digits::Args),
    /// Reconstruct a 3D scene from posed photos (a sparse voxel grid or 3D Gaussians).
    Recon(volume::ReconArgs),
    /// Render a reconstructed model from held-out cameras (PSNR, SSIM) or an orbit.
    View(volume::ViewArgs),
    /// Triangle meshes: render with exact anti-aliasing, fit to renders.
    Mesh(mesh::MeshArgs),
    /// Plot several `recon` runs' test PSNR against training time in one chart.
    Compare(compare::Args),
    /// Train every 3D representation (voxel, splat, ngp, nerf) on one scene with the same
    /// time budget: a table (test PSNR, SSIM, time, size, render time) and a chart.
    Ladder(ladder::Args),
}

/// Exit status when stdout was closed early (`diffsvg bench | head`): what a shell reports
/// for a process ended by SIGPIPE, as other tools in a pipeline end.
const CLOSED_STDOUT: u8 = 128 + 13;

/// Whether a panic's message is `println!` finding stdout closed.
fn is_closed_stdout(message: Option<&str>) -> bool {
    message.is_some_and(|m| m.starts_with("failed printing to stdout") && m.contains("Broken pipe"))
}

/// Runs the command line; returns the process exit code. A closed stdout ends the run
/// quietly with [`CLOSED_STDOUT`] (the panic `println!` raises is caught, without its
/// message; destructors run, so no temporary file is left).
pub fn main() -> ExitCode {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !is_closed_stdout(info.payload_as_str()) {
            previous(info);
        }
    }));
    match std::panic::catch_unwind(run) {
        Ok(code) => code,
        Err(payload) => {
            let message = payload
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| payload.downcast_ref::<&str>().copied());
            if is_closed_stdout(message) {
                ExitCode::from(CLOSED_STDOUT)
            } else {
                std::panic::resume_unwind(payload)
            }
        }
    }
}

fn run() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if e.use_stderr() => {
            eprintln!("error: {}", one_line(&e));
            return ExitCode::from(2);
        }
        // --help and --version: clap's own text on stdout.
        Err(e) => {
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
    };
    // A command runs on a worker of rayon's pool, so that the parallel parts of each
    // optimization step start inside the pool (a `join` the other workers may steal from)
    // instead of each being handed to the pool from outside while this thread sleeps: a
    // wake-up per parallel part, which was two thirds of a 28×28 digit step (0.18 → 0.06
    // ms on one thread, `examples/step_cost`). Workers get the main thread's stack size.
    // The benches stay on this thread: they time pools of their own, and a worker of the
    // global pool waiting on another pool keeps looking for work, taking a core from the
    // timed threads.
    const WORKER_STACK: usize = 8 << 20;
    match cli.command {
        Command::Bench(a) => dispatch(Command::Bench(a)),
        command => {
            let _ = rayon::ThreadPoolBuilder::new()
                .stack_size(WORKER_STACK)
                .build_global();
            rayon::scope(|_| dispatch(command))
        }
    }
}

/// Runs one parsed command; returns the process exit code.
fn dispatch(command: Command) -> ExitCode {
    let result = match command {
        Command::Render(a) => render::run(a),
        Command::Parity(a) => parity::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Loss(a) => grad::run_loss(a),
        Command::Grad(a) => match grad::run_grad(a) {
            Ok(grad::GradOutcome::CheckFailed) => return ExitCode::from(1),
            r => r.map(|_| ()),
        },
        Command::Fit(a) => fit::run(a),
        Command::Perturb(a) => perturb::run(a),
        Command::Vectorize(a) => vectorize::run(a),
        Command::Glyphs(a) => glyphs::run(a),
        Command::Batch(a) => return batch::main(a),
        Command::Digits(a) => digits::run(a),
        Command::Recon(a) => volume::run_recon(a),
        Command::View(a) => volume::run_view(a),
        Command::Compare(a) => compare::run(a),
        Command::Ladder(a) => ladder::run(a),
        Command::Mesh(a) => mesh::run(a),
    };
    match result {
        // A run stopped by Ctrl-C has written its best result; the status says it stopped.
        Ok(()) if progress::interrupted() => ExitCode::from(130),
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// A clap usage error as one line (every error of this tool is one line): the message
/// and, where clap gives them, the possible values and a tip, without the usage block.
pub(crate) fn one_line(e: &clap::Error) -> String {
    let text = e.render().to_string();
    let parts: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| {
            !l.is_empty() && !l.starts_with("Usage:") && !l.starts_with("For more information")
        })
        .collect();
    let line = parts.join(" ");
    line.strip_prefix("error: ").unwrap_or(&line).to_string()
}
