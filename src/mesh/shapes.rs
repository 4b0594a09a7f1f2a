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

fn normalize(p: [f64; 3]) -> [f64; 3] {
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    p.map(|v| v / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_is_closed_and_faces_outwards() {
        for s in 0..3 {
            let m = icosphere(s, 2.0);
            assert_eq!(m.triangles.len(), 20 * 4usize.pow(s));
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
