//! Generated meshes.

use std::collections::HashMap;

use super::Mesh;

/// An icosphere of `radius` centered at the origin: the icosahedron with each triangle
/// split in four `subdivisions` times (20 · 4ⁿ triangles, `subdivisions` capped at 7),
/// vertices pushed to the sphere; counter-clockwise seen from outside; no attributes.
pub fn icosphere(subdivisions: u32, radius: f64) -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pos: Vec<[f64; 3]> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .map(normalize)
    .to_vec();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions.min(7) {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::with_capacity(tris.len() * 4);
        let mut midpoint = |a: u32, b: u32, pos: &mut Vec<[f64; 3]>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let (p, q) = (pos[a as usize], pos[b as usize]);
                pos.push(normalize([p[0] + q[0], p[1] + q[1], p[2] + q[2]]));
                pos.len() as u32 - 1
            })
        };
        for &[a, b, c] in &tris {
            let ab = midpoint(a, b, &mut pos);
            let bc = midpoint(b, c, &mut pos);
            let ca = midpoint(c, a, &mut pos);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    Mesh {
        positions: pos.iter().map(|p| p.map(|v| v * radius)).collect(),
        triangles: tris,
        uvs: None,
        colors: None,
        texture: None,
    }
}

/// A (2, 3) torus knot: a tube of radius 0.25 around the curve
/// `((2 + cos 3t) cos 2t, (2 + cos 3t) sin 2t, sin 3t) / 3`, with `segments` rings of
/// `sides` vertices (`2 · segments · sides` triangles; both at least 3, at most 4096);
/// closed, counter-clockwise seen from outside, no attributes. A stand-in for a teapot:
/// a closed mesh that hides parts of itself.
pub fn torus_knot(segments: u32, sides: u32) -> Mesh {
    let (n, m) = (segments.clamp(3, 4096), sides.clamp(3, 4096));
    let curve = |t: f64| {
        let r = 2.0 + (3.0 * t).cos();
        [
            r * (2.0 * t).cos() / 3.0,
            r * (2.0 * t).sin() / 3.0,
            (3.0 * t).sin() / 3.0,
        ]
    };
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let tau = std::f64::consts::TAU;
    let mut positions = Vec::with_capacity((n * m) as usize);
    for i in 0..n {
        let t = tau * i as f64 / n as f64;
        let c = curve(t);
        // A frame: tangent by differences, normal towards the curve's second difference.
        let h = 1e-4;
        let (a, b) = (curve(t - h), curve(t + h));
        let tan = normalize(sub(b, a));
        let acc = sub([a[0] + b[0], a[1] + b[1], a[2] + b[2]], c.map(|v| 2.0 * v));
        let bin = normalize(cross(tan, acc));
        let nor = cross(bin, tan);
        for j in 0..m {
            let u = tau * j as f64 / m as f64;
            let (cu, su) = (u.cos() * 0.25, u.sin() * 0.25);
            positions.push([0, 1, 2].map(|k| c[k] + cu * nor[k] + su * bin[k]));
        }
    }
    let id = |i: u32, j: u32| (i % n) * m + (j % m);
    let mut triangles = Vec::with_capacity(2 * (n * m) as usize);
    for i in 0..n {
        for j in 0..m {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            triangles.push([a, c, b]);
            triangles.push([a, d, c]);
        }
    }
    Mesh {
        positions,
        triangles,
        uvs: None,
        colors: None,
        texture: None,
    }
}

fn normalize(p: [f64; 3]) -> [f64; 3] {
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    p.map(|v| v / n)
}

/// The regular octahedron with vertices at `±1` on each axis: 6 vertices, 8 triangles,
/// counter-clockwise seen from outside, no attributes.
pub fn octahedron() -> Mesh {
    Mesh {
        positions: vec![
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ],
        triangles: vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ],
        uvs: None,
        colors: None,
        texture: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torus_knot_is_a_closed_outward_tube() {
        let m = torus_knot(64, 8);
        assert_eq!(m.triangles.len(), 2 * 64 * 8);
        // A torus: V − E + F = 0 with E = 3F/2.
        assert_eq!(m.positions.len() * 2, m.triangles.len());
        // Every triangle faces away from its ring's center on the curve.
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let ring = (t[0] / 8) as usize;
            let center = (0..8)
                .map(|j| m.positions[ring * 8 + j])
                .fold([0.0; 3], |s, p| {
                    [s[0] + p[0] / 8.0, s[1] + p[1] / 8.0, s[2] + p[2] / 8.0]
                });
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            let out = [a[0] - center[0], a[1] - center[1], a[2] - center[2]];
            assert!(n[0] * out[0] + n[1] * out[1] + n[2] * out[2] > 0.0, "{t:?}");
        }
    }

    #[test]
    fn icosphere_and_octahedron_are_closed_and_face_outwards() {
        let meshes = (0..3).map(|s| (icosphere(s, 2.0), 20 * 4usize.pow(s)));
        for (m, n) in meshes.chain([(octahedron(), 8)]) {
            assert_eq!(m.triangles.len(), n);
            // Euler: V − E + F = 2 with E = 3F/2.
            assert_eq!(
                m.positions.len() as i64 - 3 * m.triangles.len() as i64 / 2
                    + m.triangles.len() as i64,
                2
            );
            for t in &m.triangles {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                let n = [
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ];
                assert!(n[0] * a[0] + n[1] * a[1] + n[2] * a[2] > 0.0);
            }
        }
    }
}
