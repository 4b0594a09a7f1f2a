//! Times one optimization step of a given SVG against a given picture: what `vectorize`,
//! `fit` and the bindings pay per step, on any scene (the painterly bench times random
//! blobs only).
//!
//! ```sh
//! cargo run --release --example step_cost -- SCENE.svg TARGET.png [STEPS] [WIDTH]
//! ```
//!
//! The target is resized to `WIDTH` pixels wide (default 256) and the scene scaled to the
//! same width; the objective is the MSE over white, as `vectorize` uses for an opaque
//! picture. Each of the `STEPS` rounds (default 30) prepares the scene, runs the fused
//! render + loss + gradient pass, then renders once more forward only; the medians are
//! printed in milliseconds; the rounds run on a worker of rayon's pool, as the command line
//! runs its optimizations. `RAYON_NUM_THREADS` sets the threads. The scene does not
//! move, so every round does the same work: to time a traced picture as optimization
//! leaves it, first write it with `diffsvg vectorize PICTURE --init trace -o SCENE.svg`.

use std::time::Instant;

use diffsvg::fit::Objective;
use diffsvg::image_io::Image;
use diffsvg::loss::Loss;
use diffsvg::metrics::median;
use diffsvg::raster::{self, Prepared, RenderOptions};
use diffsvg::{Scene, Sizing};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [svg, target, rest @ ..] = args.as_slice() else {
        return Err("usage: step_cost SCENE.svg TARGET.png [STEPS] [WIDTH]".into());
    };
    let steps: usize = rest.first().map_or(Ok(30), |s| s.parse())?;
    let width: u32 = rest.get(1).map_or(Ok(256), |s| s.parse())?;
    if steps == 0 || width == 0 {
        return Err("STEPS and WIDTH must be at least 1".into());
    }
    let picture = Image::load(target)?;
    let height =
        ((picture.height as f64 * width as f64 / picture.width as f64).round() as u32).max(1);
    let picture = picture.resized_checked(width, height, std::path::Path::new(target))?;
    let scene = Scene::load(svg, Sizing::Width(width))?;
    let objective = Objective::new(&picture, Loss::Mse, Some([1.0; 4]), 1);
    let opts = RenderOptions::default();
    let (mut prepare, mut step, mut forward) = (Vec::new(), Vec::new(), Vec::new());
    // On a worker of the pool, as the command line runs its optimizations.
    rayon::scope(|_| {
        for _ in 0..steps {
            let t = Instant::now();
            let p = Prepared::new(&scene, &opts);
            prepare.push(t.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(objective.render_and_backward(&scene, &p));
            step.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            std::hint::black_box(raster::render(&scene, &opts));
            forward.push(t.elapsed().as_secs_f64() * 1e3);
        }
    });
    let (prepare, step, forward) = (
        median(&mut prepare),
        median(&mut step),
        median(&mut forward),
    );
    println!(
        "{} paths at {width}×{height}, {} threads, medians of {steps}: step {step:.2} ms \
         (of which preparing {prepare:.2}), forward {forward:.2} ms, step/forward {:.2}",
        scene.path_count(),
        rayon::current_num_threads(),
        step / forward
    );
    Ok(())
}
