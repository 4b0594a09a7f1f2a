//! `diffsvg mesh render`, `mesh fit` and `bench mesh` on a tiny generated mesh (no data
//! needed), and `mesh render` on spot when the shared data is there.

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
fn mesh_fit_moves_a_sphere_towards_a_generated_mesh_and_writes_an_obj() {
    let d = scratch("mesh_fit");
    let obj = octahedron(&d);
    let out = d.join("fit.obj");
    let r = diffsvg(&[
        "mesh",
        "fit",
        s(&obj),
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
        "--quiet",
        "-o",
        s(&out),
    ]);
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // "held-out PSNR A → B dB": the fit improves the held-out views.
    let tail = stdout
        .split("held-out PSNR ")
        .nth(1)
        .expect("held-out PSNR printed");
    let nums: Vec<f64> = tail
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter_map(|t| t.parse().ok())
        .take(2)
        .collect();
    assert!(nums[1] > nums[0] + 1.0, "{stdout}");
    let fitted = diffsvg::mesh::read_obj(&out).unwrap();
    assert_eq!(fitted.triangles.len(), 80);
    assert!(fitted.colors.is_some(), "vertex colors written");
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
