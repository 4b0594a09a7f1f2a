//! `diffsvg mesh render`, `mesh fit` and `bench mesh` on a tiny generated mesh (no data
//! needed), `mesh refine` and `mesh simplify` on a tiny textured octahedron, and `mesh
//! render` on spot when the shared data is there.

use super::common::{assert_fails, diffsvg, s, scratch, shared_data, write};

/// An octahedron with a red material: 6 vertices, 8 counter-clockwise faces.
fn octahedron(dir: &std::path::Path) -> std::path::PathBuf {
    write(dir, "octa.mtl", "newmtl red\nKd 0.9 0.1 0.1\n");
    write(
        dir,
        "octa.obj",
        "mtllib octa.mtl\nv 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\nusemtl red\n\
         f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n",
    )
}

/// `diffsvg mesh render MESH --orbit 2 --size 32 -o OUT`, which must succeed; the image.
fn render_two_views(mesh: &std::path::Path, out: &std::path::Path) -> diffsvg::Image {
    let r = diffsvg(&[
        "mesh",
        "render",
        s(mesh),
        "--orbit",
        "2",
        "--size",
        "32",
        "-o",
        s(out),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    diffsvg::Image::load(out).unwrap()
}

#[test]
fn mesh_render_draws_a_generated_mesh_and_refuses_bad_files() {
    let d = scratch("mesh_render");
    let obj = octahedron(&d);
    let img = render_two_views(&obj, &d.join("octa.png"));
    assert_eq!((img.width, img.height), (64, 32));
    // Red inside, white around, and anti-aliased pixels between.
    let red = img
        .data
        .iter()
        .filter(|p| p[0] > 0.85 && p[1] < 0.15)
        .count();
    let white = img.data.iter().filter(|p| p[1] > 0.99).count();
    let edge = img.data.iter().filter(|p| p[1] > 0.2 && p[1] < 0.8).count();
    assert!(
        red > 50 && white > 500 && edge > 10,
        "{red} red, {white} white, {edge} edge"
    );

    let bad = write(&d, "bad.obj", "v 0 0 0\nv 1 0 0\nf 1 2 7\n");
    let out2 = d.join("bad.png");
    let r = diffsvg(&["mesh", "render", s(&bad), "-o", s(&out2)]);
    assert_fails(&r, "bad.obj", "malformed obj", &out2);
    let r = diffsvg(&["mesh", "render", s(&d.join("absent.obj")), "-o", s(&out2)]);
    assert_fails(&r, "absent.obj", "no such file", &out2);
}

#[test]
fn mesh_render_shades_with_lights_and_refuses_bad_ones() {
    let d = scratch("mesh_render_lights");
    let obj = octahedron(&d);
    let unlit = render_two_views(&obj, &d.join("unlit.png"));
    let render = |name: &str, extra: &[&str]| {
        let out = d.join(name);
        let mut args = vec!["mesh", "render", s(&obj), "--orbit", "2", "--size", "32"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["-o", s(&out)]);
        (diffsvg(&args), out)
    };
    // A white ambient light alone is the unlit image.
    let (r, out) = render("white.png", &["--ambient", "1,1,1"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(diffsvg::Image::load(&out).unwrap(), unlit);
    // One light from above: faces turned up are brighter than faces turned down, and no
    // pixel is brighter than the albedo under ambient + intensity.
    let (r, out) = render("lit.png", &["--light", "0,1,0", "--ambient", "0.1,0.1,0.1"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let lit = diffsvg::Image::load(&out).unwrap();
    assert_ne!(lit, unlit);
    let h = lit.height as usize;
    let w = lit.width as usize;
    let reds = |rows: std::ops::Range<usize>| {
        let v: Vec<f32> = rows
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| lit.data[y * w + x])
            .filter(|p| p[1] < 0.5)
            .map(|p| p[0])
            .collect();
        v.iter().sum::<f32>() / v.len().max(1) as f32
    };
    let (top, bottom) = (reds(0..h / 2), reds(h / 2..h));
    assert!(top > bottom + 0.1, "top {top} bottom {bottom}");
    assert!(
        lit.data
            .iter()
            .all(|p| p[0] <= 0.9 * 1.1 + 1e-3 || p[1] > 0.5)
    );
    for (flag, value, what) in [
        ("--light", "0,0,0", "zero"),
        ("--light", "1,2", "2 numbers"),
        ("--ambient", "1,x,1", "not a finite number"),
    ] {
        let (r, out) = render("bad.png", &[flag, value]);
        assert_fails(&r, flag, what, &out);
    }
    let five: Vec<&str> = ["--light", "0,1,0"].repeat(5);
    let (r, out) = render("bad.png", &five);
    assert_fails(&r, "--light", "at most 4", &out);
}

/// `mesh fit MESH` from a once-subdivided sphere: 3 training and 2 held-out views at
/// 24², 30 steps, written to `out`, with `extra` flags.
fn small_fit(
    mesh: &std::path::Path,
    out: &std::path::Path,
    extra: &[&str],
) -> std::process::Output {
    let mut args = vec![
        "mesh",
        "fit",
        s(mesh),
        "--views",
        "3",
        "--test-views",
        "2",
        "--size",
        "24",
        "--iters",
        "30",
        "--subdivisions",
        "1",
        "--lr-positions",
        "0.02",
        "--lr-colors",
        "0.05",
        "-o",
        s(out),
    ];
    args.extend_from_slice(extra);
    diffsvg(&args)
}

#[test]
fn mesh_fit_moves_a_sphere_towards_a_generated_mesh_and_writes_an_obj() {
    let d = scratch("mesh_fit");
    let obj = octahedron(&d);
    let out = d.join("fit.obj");
    // One fit, written to `out` (OBJ or glTF by its extension).
    let run = |out: &std::path::Path| small_fit(&obj, out, &["--quiet"]);
    let r = run(&out);
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // "held-out PSNR A → B dB": the fit improves the held-out views.
    let (before, after) = held_out_psnr(&stdout);
    assert!(after > before + 1.0, "{stdout}");
    let fitted = diffsvg::mesh::read_obj(&out).unwrap();
    assert_eq!(fitted.triangles.len(), 80);
    assert!(fitted.colors.is_some(), "vertex colors written");
    // The same fit written as glTF: the same mesh (the fit is deterministic).
    let glb = d.join("fit.glb");
    let r = run(&glb);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let back = diffsvg::mesh::read_gltf(&glb).unwrap();
    assert_eq!(back.triangles.len(), 80);
    let near = |a: &[[f64; 3]], b: &[[f64; 3]]| {
        let mut a: Vec<_> = a
            .iter()
            .map(|p| p.map(|v| (v * 1e4).round() as i64))
            .collect();
        let mut b: Vec<_> = b
            .iter()
            .map(|p| p.map(|v| (v * 1e4).round() as i64))
            .collect();
        a.sort_unstable();
        b.sort_unstable();
        a.iter()
            .zip(&b)
            .all(|(p, q)| (0..3).all(|k| (p[k] - q[k]).abs() <= 1))
    };
    assert!(near(&back.positions, &fitted.positions));
    let txt = d.join("fit.txt");
    assert_fails(&run(&txt), "fit.txt", ".glb", &txt);
}

/// Every JSON object `stdout` prints, one a line.
fn json_lines(stdout: &[u8]) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(stdout)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

#[test]
fn mesh_fit_logs_held_out_psnr_against_time_and_plots_it() {
    let d = scratch("mesh_fit_log");
    let obj = octahedron(&d);
    let out = d.join("fit.obj");
    let r = small_fit(&obj, &out, &["--eval-every", "10", "--json"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let lines = json_lines(&r.stdout);
    let summary = lines.last().unwrap();
    assert_eq!(summary["done"], true, "{summary}");
    // Held-out PSNR at steps 0, 10, 20 and at the end (30), one JSON row each.
    let rows: Vec<(u64, f64, f64)> = lines
        .iter()
        .filter(|l| l.get("test_psnr").is_some() && l.get("done").is_none())
        .map(|l| {
            (
                l["iteration"].as_u64().unwrap(),
                l["seconds"].as_f64().unwrap(),
                l["test_psnr"].as_f64().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        rows.iter().map(|r| r.0).collect::<Vec<_>>(),
        [0, 10, 20, 30],
        "{rows:?}"
    );
    assert!(
        rows.windows(2).all(|w| w[1].1 >= w[0].1),
        "time runs forward: {rows:?}"
    );
    let (first, last) = (rows[0].2, rows[3].2);
    assert!(last > first + 1.0, "held-out PSNR rises: {rows:?}");
    assert_eq!(summary["test_psnr"].as_f64().unwrap(), last);
    // The log: the same held-out PSNRs (3 decimals) and a training PSNR every step.
    let log = std::fs::read_to_string(d.join("fit.log.csv")).unwrap();
    let mut it = log.lines();
    assert_eq!(it.next(), Some("iteration,seconds,train_psnr,test_psnr"));
    let cells: Vec<Vec<&str>> = it.map(|l| l.split(',').collect()).collect();
    assert_eq!(cells.len(), 31, "{log}");
    let tests: Vec<f64> = cells.iter().filter_map(|c| c[3].parse().ok()).collect();
    assert_eq!(tests.len(), 4, "{log}");
    for (t, r) in tests.iter().zip(&rows) {
        assert!((t - r.2).abs() < 1e-3, "{log}");
    }
    // The plot, as PNG and SVG.
    let png = diffsvg::Image::load(d.join("fit.psnr.png")).unwrap();
    assert!(png.width > 100 && png.height > 100);
    let svg = std::fs::read_to_string(d.join("fit.psnr.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("PSNR"), "{svg}");
}

#[test]
fn mesh_fit_refines_perturbed_poses_and_fits_lights() {
    let d = scratch("mesh_fit_poses");
    let obj = octahedron(&d);
    let out = d.join("fit.obj");
    // The model starts as the reference itself; only the cameras or the lights are off.
    let run = |extra: &[&str]| {
        let mut args = vec![
            "mesh",
            "fit",
            s(&obj),
            "--start",
            s(&obj),
            "--views",
            "4",
            "--test-views",
            "2",
            "--size",
            "32",
            "--iters",
            "40",
            "--lr-positions",
            "0",
            "--lr-colors",
            "0",
            "--json",
            "-o",
            s(&out),
        ];
        args.extend_from_slice(extra);
        diffsvg(&args)
    };
    let r = run(&["--refine-poses", "--perturb-poses", "1,0.01"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let summary = json_lines(&r.stdout).pop().unwrap();
    let e = &summary["pose_error"];
    let (before, after) = (
        e["before"]["degrees"].as_f64().unwrap(),
        e["after"]["degrees"].as_f64().unwrap(),
    );
    assert!((before - 1.0).abs() < 1e-3, "{summary}");
    assert!(after < 0.5 * before, "{summary}");
    // The scene's motion photos cannot tell, and the error left in the model's frame.
    for key in ["frame", "after_in_frame"] {
        for part in ["degrees", "units"] {
            let v = e[key][part].as_f64().unwrap_or(f64::NAN);
            assert!(v.is_finite() && v >= 0.0, "{key} {part}: {summary}");
        }
    }
    assert!(
        e["after_in_frame"]["degrees"].as_f64().unwrap() < 0.5 * before,
        "{summary}"
    );
    // One correction per training view; the held-out views keep their cameras.
    assert_eq!(summary["pose_corrections"], 4, "{summary}");
    // Lights: the reference lit from (0.3, 0.8, 0.5), the model's light starting 34.9°
    // away (5.4° when written).
    let truth = [0.3, 0.8, 0.5];
    let r = run(&[
        "--reference-light",
        "0.3,0.8,0.5",
        "--light",
        "0.7,0.65,0.1",
        "--ambient",
        "0.2,0.2,0.2",
        "--fit-lights",
        "--lr-lights",
        "0.01",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let summary = json_lines(&r.stdout).pop().unwrap();
    let dir: Vec<f64> = summary["lighting"]["lights"][0]["direction"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let angle = |a: &[f64], b: &[f64]| {
        let n = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let c = a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>() / (n(a) * n(b));
        c.clamp(-1.0, 1.0).acos().to_degrees()
    };
    let (start, end) = (angle(&[0.7, 0.65, 0.1], &truth), angle(&dir, &truth));
    assert!(
        end < 0.5 * start,
        "light {start:.1}° → {end:.1}° off: {summary}"
    );
    // Bad flags: one line naming them, no output.
    std::fs::remove_file(&out).unwrap();
    assert_fails(&run(&["--fit-lights"]), "--fit-lights", "--light", &out);
    assert_fails(
        &run(&["--reference-light", "0,1,0"]),
        "--reference-light",
        "--fit-lights",
        &out,
    );
    assert_fails(&run(&["--lr-uvs", "0.1"]), "--lr-uvs", "texture", &out);
    assert_fails(
        &run(&["--refine-poses", "--perturb-poses", "200,0"]),
        "--perturb-poses",
        "degrees",
        &out,
    );
}

#[test]
fn bench_mesh_prints_a_table() {
    let d = scratch("mesh_bench");
    let obj = octahedron(&d);
    let r = diffsvg(&[
        "bench",
        "mesh",
        s(&obj),
        "--size",
        "32",
        "--runs",
        "2",
        "--threads",
        "1,2",
    ]);
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(
        stdout
            .lines()
            .filter(|l| l.starts_with("| 1 |") || l.starts_with("| 2 |"))
            .count(),
        2,
        "{stdout}"
    );
}

#[test]
fn bench_mesh_tutorial_gives_a_camera_gradient() {
    let r = diffsvg(&[
        "bench",
        "mesh",
        "--tutorial",
        "--size",
        "48",
        "--runs",
        "1",
        "--threads",
        "1,2",
    ]);
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(stdout.contains("2560 triangles"), "{stdout}");
    // | threads | ms | loss | (gx, gy, gz) |: a positive loss (the two silhouettes
    // differ) and a nonzero gradient, the same on one and two threads.
    let rows: Vec<Vec<&str>> = stdout
        .lines()
        .filter(|l| l.starts_with("| 1 |") || l.starts_with("| 2 |"))
        .map(|l| l.split('|').map(str::trim).collect())
        .collect();
    assert_eq!(rows.len(), 2, "{stdout}");
    assert!(rows[0][3].parse::<f64>().unwrap() > 0.0, "{stdout}");
    assert!(rows[0][4] != "(0.000, 0.000, 0.000)", "{stdout}");
    assert_eq!(rows[0][3..], rows[1][3..], "{stdout}");
}

#[test]
fn mesh_render_draws_spot() {
    let Some(data) = shared_data("mesh_render_draws_spot") else {
        return;
    };
    let spot = data.join("meshes/spot/spot.obj");
    let d = scratch("mesh_spot");
    let out = d.join("spot.png");
    let r = diffsvg(&["mesh", "render", s(&spot), "--size", "64", "-o", s(&out)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let img = diffsvg::Image::load(&out).unwrap();
    let covered = img
        .data
        .iter()
        .filter(|p| p[0] < 0.95 || p[2] < 0.95)
        .count();
    assert!(covered > 300, "{covered} pixels show the cow");
}

/// The octahedron as glTF: positions and indices in a base64 data URI, the red as a
/// linear base color factor (glTF's colors are linear; diffsvg keeps sRGB values).
fn octahedron_gltf(dir: &std::path::Path) -> std::path::PathBuf {
    use base64::Engine as _;
    let linear = |c: f64| ((c + 0.055) / 1.055).powf(2.4);
    let mut buf = Vec::new();
    for p in [
        [1.0f32, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ] {
        for v in p {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    let faces = [
        [1u32, 3, 5],
        [3, 2, 5],
        [2, 4, 5],
        [4, 1, 5],
        [3, 1, 6],
        [2, 3, 6],
        [4, 2, 6],
        [1, 4, 6],
    ];
    for i in faces.iter().flatten() {
        buf.extend_from_slice(&(i - 1).to_le_bytes());
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"material":0}}]}}],
        "materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[{},{},{},1]}}}}],
        "buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}}],
        "bufferViews":[{{"buffer":0,"byteLength":72}},{{"buffer":0,"byteOffset":72,"byteLength":96}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":6,"type":"VEC3","min":[-1,-1,-1],"max":[1,1,1]}},
                     {{"bufferView":1,"componentType":5125,"count":24,"type":"SCALAR"}}]}}"#,
        linear(0.9),
        linear(0.1),
        linear(0.1),
        buf.len(),
        base64::engine::general_purpose::STANDARD.encode(&buf)
    );
    write(dir, "octa.gltf", &json)
}

/// `mesh render` draws the same octahedron from OBJ and from glTF; a broken glTF is one
/// line naming the file.
#[test]
fn mesh_render_reads_gltf_like_obj() {
    let d = scratch("mesh_gltf");
    let (obj, gltf) = (octahedron(&d), octahedron_gltf(&d));
    let mut images = Vec::new();
    for (input, name) in [(&obj, "obj.png"), (&gltf, "gltf.png")] {
        images.push(render_two_views(input, &d.join(name)));
    }
    let worst = images[0]
        .data
        .iter()
        .zip(&images[1].data)
        .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs()))
        .fold(0.0f32, f32::max);
    assert!(
        worst <= 1.0 / 255.0,
        "OBJ and glTF renders differ by {worst}"
    );
    let bad = write(
        &d,
        "bad.gltf",
        r#"{"asset":{"version":"2.0"},"meshes":[{"primitives":[]}]}"#,
    );
    let out = d.join("bad.png");
    let r = diffsvg(&["mesh", "render", s(&bad), "-o", s(&out)]);
    assert_fails(&r, "bad.gltf", "", &out);
}

/// Writes a NeRF-synthetic folder whose photos are `mesh`'s own renders over white
/// (`n_train` and `n_test` views of `size²`, cameras around the origin, +Z up).
fn mesh_scene(dir: &std::path::Path, mesh: &diffsvg::mesh::Mesh, n_train: usize, n_test: usize) {
    use diffsvg::volume::camera::Camera;
    use glam::Vec3;
    const FOV: f32 = 0.7;
    let opts = diffsvg::mesh::RenderOptions {
        background: Some([1.0; 3]),
        ..Default::default()
    };
    for (split, n, phase) in [("train", n_train, 0.0f32), ("test", n_test, 0.9)] {
        std::fs::create_dir_all(dir.join(split)).unwrap();
        let frames: Vec<String> = (0..n)
            .map(|i| {
                let a = phase + i as f32 * std::f32::consts::TAU / n as f32;
                let eye = Vec3::new(3.5 * a.cos(), 3.5 * a.sin(), 1.2);
                let cam = Camera::look_at(eye, Vec3::ZERO, Vec3::Z, FOV, 40, 40).unwrap();
                diffsvg::mesh::render(mesh, &cam, &opts)
                    .unwrap()
                    .save_png(dir.join(format!("{split}/r_{i}.png")))
                    .unwrap();
                let (m, t) = (cam.c2w.matrix3, cam.c2w.translation);
                let row =
                    |r: usize| format!("[{}, {}, {}, {}]", m.x_axis[r], m.y_axis[r], m.z_axis[r], t[r]);
                format!(
                    "{{\"file_path\": \"./{split}/r_{i}\", \"transform_matrix\": [{}, {}, {}, [0, 0, 0, 1]]}}",
                    row(0),
                    row(1),
                    row(2)
                )
            })
            .collect();
        std::fs::write(
            dir.join(format!("transforms_{split}.json")),
            format!(
                "{{\"camera_angle_x\": {FOV}, \"frames\": [{}]}}",
                frames.join(", ")
            ),
        )
        .unwrap();
    }
}

/// A unit icosphere (2 subdivisions) with a smooth color per vertex, in [0.1, 0.9].
fn colored_sphere() -> diffsvg::mesh::Mesh {
    let mut m = diffsvg::mesh::icosphere(2, 1.0);
    m.colors = Some(
        m.positions
            .iter()
            .map(|p| p.map(|v| 0.5 + 0.4 * v))
            .collect(),
    );
    m
}

/// The two numbers of "held-out PSNR A → B dB" in a `mesh fit` or `mesh simplify` report.
fn held_out_psnr(stdout: &str) -> (f64, f64) {
    let tail = stdout
        .split("held-out PSNR ")
        .nth(1)
        .expect("held-out PSNR printed");
    let nums: Vec<f64> = tail
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter_map(|t| t.parse().ok())
        .take(2)
        .collect();
    (nums[0], nums[1])
}

/// The last line of `stdout`, as JSON (`view --json`'s summary).
fn last_json(stdout: &[u8]) -> serde_json::Value {
    let text = String::from_utf8_lossy(stdout);
    serde_json::from_str(text.trim().lines().last().unwrap()).unwrap()
}

#[test]
fn view_renders_a_mesh_from_a_dataset_s_cameras_and_an_orbit() {
    let d = scratch("mesh_view");
    let mut m = colored_sphere();
    let scene = d.join("scene");
    mesh_scene(&scene, &m, 3, 2);
    let obj = d.join("sphere.obj");
    diffsvg::mesh::write_obj(&m, &obj).unwrap();
    let view = |mesh: &std::path::Path, out: &str, extra: &[&str]| {
        let out = d.join(out);
        let mut args = vec![
            "view",
            s(mesh),
            "--scene",
            s(&scene),
            "-o",
            s(&out),
            "--json",
        ];
        args.extend_from_slice(extra);
        (diffsvg(&args), out)
    };
    // Its own renders: only the photos' 8-bit rounding differs.
    let (r, out) = view(&obj, "same", &["--orbit", "2"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let v = last_json(&r.stdout);
    assert_eq!(v["views"], 2);
    assert!(v["psnr"].as_f64().unwrap() > 45.0, "{v}");
    for f in [
        "r_0.png",
        "r_1.png",
        "metrics.csv",
        "orbit-001.png",
        "orbit.gif",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    // The same sphere moved by a tenth of its radius: clearly worse.
    m.positions.iter_mut().for_each(|p| p[0] += 0.1);
    let moved = d.join("moved.obj");
    diffsvg::mesh::write_obj(&m, &moved).unwrap();
    let (r, _) = view(&moved, "moved", &[]);
    let v = last_json(&r.stdout);
    assert!(v["psnr"].as_f64().unwrap() < 30.0, "{v}");
    // Depth images are not drawn for meshes: one line, nothing written.
    let (r, out) = view(&obj, "depth", &["--depth"]);
    assert_fails(&r, "--depth", "voxel", &out);
}

/// A textured octahedron: each face its own UV triangle in a 4 × 2 grid (UV seams on every
/// edge), an 8 × 8 texture of colored stripes.
fn textured_octahedron(dir: &std::path::Path) -> std::path::PathBuf {
    let mut tex = diffsvg::Image::new(8, 8);
    for (i, p) in tex.data.iter_mut().enumerate() {
        let (x, y) = (i % 8, i / 8);
        *p = [0.2 + 0.1 * x as f32, 0.9 - 0.1 * y as f32, 0.3, 1.0];
    }
    tex.save_png(dir.join("stripes.png")).unwrap();
    write(dir, "tocta.mtl", "newmtl t\nKd 1 1 1\nmap_Kd stripes.png\n");
    let mut obj = String::from("mtllib tocta.mtl\nusemtl t\n");
    for p in ["1 0 0", "-1 0 0", "0 1 0", "0 -1 0", "0 0 1", "0 0 -1"] {
        obj += &format!("v {p}\n");
    }
    let faces = [
        [1, 3, 5],
        [3, 2, 5],
        [2, 4, 5],
        [4, 1, 5],
        [3, 1, 6],
        [2, 3, 6],
        [4, 2, 6],
        [1, 4, 6],
    ];
    for (f, face) in faces.iter().enumerate() {
        let (u0, v0) = ((f % 4) as f64 * 0.25, (f / 4) as f64 * 0.5);
        obj += &format!(
            "vt {} {}\nvt {} {}\nvt {} {}\n",
            u0 + 0.02,
            v0 + 0.02,
            u0 + 0.23,
            v0 + 0.02,
            u0 + 0.02,
            v0 + 0.45
        );
        let t = 3 * f + 1;
        obj += &format!(
            "f {}/{} {}/{} {}/{}\n",
            face[0],
            t,
            face[1],
            t + 1,
            face[2],
            t + 2
        );
    }
    write(dir, "tocta.obj", &obj)
}

/// `mesh refine` then `mesh simplify` on a tiny reference: the triangle counts, and the
/// optimized low-poly mesh beats the classic simplification on held-out views.
#[test]
fn mesh_simplify_improves_on_the_classic_simplification() {
    let d = scratch("mesh_simplify");
    let obj = textured_octahedron(&d);
    let reference = d.join("ref.obj");
    let r = diffsvg(&[
        "mesh",
        "refine",
        s(&obj),
        "--levels",
        "3",
        "--displace",
        "0.08",
        "--frequency",
        "4",
        "-o",
        s(&reference),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let refined = diffsvg::mesh::read_obj(&reference).unwrap();
    assert_eq!(refined.triangles.len(), 8 * 64);
    assert!(refined.texture.is_some(), "the texture is kept");

    let (out, classic) = (d.join("low.obj"), d.join("classic.obj"));
    let r = diffsvg(&[
        "mesh",
        "simplify",
        s(&reference),
        "--triangles",
        "60",
        "--views",
        "16",
        "--test-views",
        "6",
        "--size",
        "32",
        "--iters",
        "40",
        "--texture-size",
        "32",
        "--lr-positions",
        "0.005",
        "--lr-colors",
        "0.03",
        "--classic",
        s(&classic),
        "--quiet",
        "-o",
        s(&out),
    ]);
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let psnr = |name: &str| -> f64 {
        let tail = stdout.split(name).nth(1).expect("PSNR printed");
        tail.split(|c: char| !(c.is_ascii_digit() || c == '.'))
            .find_map(|t| t.parse().ok())
            .unwrap()
    };
    let (before, after) = (psnr("classic "), psnr("optimized "));
    // 32.19 → 38.30 dB when written; 8 views instead of 16 overfit (+0.4 dB).
    assert!(after > before + 2.0, "{stdout}");
    for path in [&out, &classic] {
        let m = diffsvg::mesh::read_obj(path).unwrap();
        assert!(
            m.triangles.len() <= 60 && m.triangles.len() >= 40,
            "{path:?}"
        );
        assert!(m.texture.is_some(), "{path:?} textured");
    }

    // Bad files and flags: one line naming the file or flag, exit 2, no output.
    let bad_out = d.join("bad.obj");
    let plain = octahedron(&d);
    let absent = d.join("absent.obj");
    let (r, p, o) = (s(&reference), s(&plain), s(&obj));
    for (args, needle, what) in [
        (vec!["simplify", s(&absent)], "absent.obj", "no such file"),
        (vec!["simplify", p], "octa.obj", "no uvs"),
        (
            vec!["simplify", r, "--triangles", "0"],
            "--triangles",
            "between",
        ),
        (vec!["refine", o, "--levels", "20"], "--levels", "at most"),
        (vec!["refine", o, "--displace=-1"], "--displace", "negative"),
    ] {
        let mut all = vec!["mesh"];
        all.extend(args);
        all.extend(["-o", s(&bad_out)]);
        assert_fails(&diffsvg(&all), needle, what, &bad_out);
    }
}

#[test]
fn mesh_fit_fits_a_dataset_s_photos() {
    let d = scratch("mesh_fit_scene");
    let m = colored_sphere();
    let scene = d.join("scene");
    mesh_scene(&scene, &m, 4, 2);
    let out = d.join("fit.obj");
    let args = [
        "mesh",
        "fit",
        "--scene",
        s(&scene),
        "--iters",
        "40",
        "--subdivisions",
        "2",
        "--lr-positions",
        "0.01",
        "--lr-colors",
        "0.05",
        "--quiet",
        "-o",
        s(&out),
    ];
    let r = diffsvg(&args);
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let (before, after) = held_out_psnr(&stdout);
    assert!(after > before + 3.0, "{stdout}");
    assert!(
        stdout.contains("to 4 views at 40²") && stdout.contains("over 2 views"),
        "{stdout}"
    );
    // Neither a reference nor a scene, or both: refused before anything is written.
    let r = diffsvg(&["mesh", "fit", "-o", s(&out)]);
    assert_eq!(r.status.code(), Some(2));
    let obj = octahedron(&d);
    let r = diffsvg(&[
        "mesh",
        "fit",
        s(&obj),
        "--scene",
        s(&scene),
        "-o",
        s(&d.join("b.obj")),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(!d.join("b.obj").exists());
}
