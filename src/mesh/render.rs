//! Forward and backward rendering of a [`Mesh`] through one camera: the exact visible
//! area of each triangle in each pixel (see the conventions in [`crate::mesh`]).
//!
//! Per view: vertices go to camera space, triangles are culled and clipped against the
//! near plane, projected, and binned by pixel row. Per pixel: each candidate triangle's
//! fragment (triangle ∩ pixel square, a convex polygon) is cut by every triangle that is
//! in front of it on their common part (depth compared at the centroid of that overlap),
//! and what is left is its visible area. Every piece vertex is a projected vertex, a
//! pixel corner or the crossing of two lines, so the backward pass runs reverse-mode
//! through the clipping (`mesh/geom.rs`) and then through the projection.
//!
//! Rows are independent; the backward pass collects each row's contributions in a list
//! and adds the lists in row order, so results are the same bits on any number of
//! threads.

use rayon::prelude::*;

use super::geom::{self, GradSink, Line, Poly};
use super::{Mesh, Texture};
use crate::Image;
use crate::error::{Error, Result};
use crate::volume::camera::Camera;

/// How a mesh is rendered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Straight RGB background in `[0, 1]`; `None` leaves uncovered area transparent.
    pub background: Option<[f64; 3]>,
    /// Skip triangles seen from behind (exact for closed meshes, and faster).
    pub cull_back_faces: bool,
    /// Near-plane distance in front of the camera, world units (> 0).
    pub near: f64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            background: None,
            cull_back_faces: true,
            near: 1e-3,
        }
    }
}

/// Gradients of a scalar loss with respect to a mesh's parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshGrad {
    /// Per vertex position, world units.
    pub positions: Vec<[f64; 3]>,
    /// Per vertex color, when the mesh has colors.
    pub colors: Option<Vec<[f64; 3]>>,
    /// Per texel, when the mesh has a texture.
    pub texture: Option<Vec<[f64; 3]>>,
}

/// Where a screen vertex comes from.
#[derive(Clone, Copy, Debug)]
enum Src {
    /// Mesh vertex `i` projected.
    Vert(u32),
    /// The crossing of camera-space edge `a → b` with the near plane, projected.
    Clip(u32, u32),
}

/// A projected (and near-clipped) triangle: a convex counter-clockwise polygon of 3 or
/// 4 screen vertices.
#[derive(Clone, Copy, Debug)]
struct Prim {
    tri: u32,
    n: u8,
    sv: [u32; 4],
    lo: [f64; 2],
    hi: [f64; 2],
    /// Camera-space plane normal `(P1 − P0) × (P2 − P0)` and `normal · P0`.
    normal: [f64; 3],
    nd: f64,
}

impl Prim {
    fn edges(&self) -> impl Iterator<Item = Line> + '_ {
        let n = self.n as usize;
        (0..n).map(move |k| Line::Edge(self.sv[k], self.sv[(k + 1) % n]))
    }
}

/// Rendering one mesh through one camera: the public handle on a prepared view.
pub struct View<'a> {
    mesh: &'a Mesh,
    opts: RenderOptions,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    /// World-to-camera rotation rows.
    rot: [[f64; 3]; 3],
    pc: Vec<[f64; 3]>,
    sv: Vec<[f64; 2]>,
    src: Vec<Src>,
    prims: Vec<Prim>,
    row_start: Vec<u32>,
    row_prims: Vec<u32>,
}

#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline]
fn axpy(y: &mut [f64; 3], a: f64, x: [f64; 3]) {
    y[0] += a * x[0];
    y[1] += a * x[1];
    y[2] += a * x[2];
}

/// Smallest overlap (pixel area) that decides an occlusion; below it two fragments are
/// taken as touching (shared edges leave slivers of round-off size).
const MIN_OVERLAP: f64 = 1e-12;

impl<'a> View<'a> {
    /// Projects, culls, clips and bins `mesh` for `camera`. Refuses cameras with lens
    /// distortion and a near plane that is not positive and finite; the mesh should be
    /// [`validated`](Mesh::validate) (indices in range, finite values).
    pub fn new(mesh: &'a Mesh, camera: &Camera, opts: RenderOptions) -> Result<View<'a>> {
        let setting = |name: &str, message: String| Error::Setting {
            name: name.into(),
            message,
        };
        if camera.has_distortion() {
            return Err(setting(
                "camera",
                "has lens distortion: meshes render through pinhole cameras only".into(),
            ));
        }
        camera
            .validate()
            .map_err(|e| setting("camera", e.to_string()))?;
        if !(opts.near > 0.0 && opts.near.is_finite()) {
            return Err(setting(
                "near",
                format!("{} must be positive and finite", opts.near),
            ));
        }
        if let Some(bg) = opts.background
            && !bg.iter().all(|v| v.is_finite())
        {
            return Err(setting("background", format!("{bg:?} is not finite")));
        }
        let m = camera.c2w.matrix3;
        let rot = [m.x_axis, m.y_axis, m.z_axis].map(|a| [a.x as f64, a.y as f64, a.z as f64]);
        let t = camera.c2w.translation;
        let eye = [t.x as f64, t.y as f64, t.z as f64];
        let mut view = View {
            mesh,
            opts,
            width: camera.width,
            height: camera.height,
            fx: camera.fx as f64,
            fy: camera.fy as f64,
            cx: camera.cx as f64,
            cy: camera.cy as f64,
            rot,
            pc: Vec::with_capacity(mesh.positions.len()),
            sv: Vec::new(),
            src: Vec::new(),
            prims: Vec::new(),
            row_start: Vec::new(),
            row_prims: Vec::new(),
        };
        view.pc = mesh
            .positions
            .iter()
            .map(|&p| {
                let d = sub(p, eye);
                [dot(rot[0], d), dot(rot[1], d), dot(rot[2], d)]
            })
            .collect();
        view.build_prims();
        view.bin_rows();
        Ok(view)
    }

    #[inline]
    fn project(&self, p: [f64; 3]) -> [f64; 2] {
        // x = cx + fx·X/(−Z), y = cy + fy·Y/Z (image y down, camera Y up).
        [
            self.cx - self.fx * p[0] / p[2],
            self.cy + self.fy * p[1] / p[2],
        ]
    }

    fn clip_point(&self, a: u32, b: u32) -> [f64; 3] {
        let (pa, pb) = (self.pc[a as usize], self.pc[b as usize]);
        let t = (pa[2] + self.opts.near) / (pa[2] - pb[2]);
        [
            pa[0] + t * (pb[0] - pa[0]),
            pa[1] + t * (pb[1] - pa[1]),
            -self.opts.near,
        ]
    }

    fn build_prims(&mut self) {
        let near = self.opts.near;
        let mut vert_sv = vec![u32::MAX; self.pc.len()];
        let (w, h) = (self.width as f64, self.height as f64);
        for (ti, tri) in self.mesh.triangles.iter().enumerate() {
            let p = tri.map(|i| self.pc[i as usize]);
            let normal = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            let nd = dot(normal, p[0]);
            // The camera is at the origin: a front face has its normal towards it.
            if !(nd.is_finite() && nd != 0.0) || (self.opts.cull_back_faces && nd > 0.0) {
                continue;
            }
            let inside = p.map(|q| -q[2] >= near);
            if !inside.iter().any(|&b| b) {
                continue;
            }
            let mut ids = [0u32; 4];
            let mut n = 0usize;
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                if inside[k] {
                    if vert_sv[a as usize] == u32::MAX {
                        vert_sv[a as usize] = self.sv.len() as u32;
                        self.sv.push(self.project(p[k]));
                        self.src.push(Src::Vert(a));
                    }
                    ids[n] = vert_sv[a as usize];
                    n += 1;
                }
                if inside[k] != inside[(k + 1) % 3] {
                    let q = self.clip_point(a, b);
                    ids[n] = self.sv.len() as u32;
                    n += 1;
                    self.sv.push(self.project(q));
                    self.src.push(Src::Clip(a, b));
                }
            }
            let pts: Vec<[f64; 2]> = ids[..n].iter().map(|&i| self.sv[i as usize]).collect();
            let mut s = 0.0;
            for k in 0..n {
                let (a, b) = (pts[k], pts[(k + 1) % n]);
                s += a[0] * b[1] - b[0] * a[1];
            }
            if !(s.is_finite() && s != 0.0) {
                continue;
            }
            if s < 0.0 {
                ids[..n].reverse();
            }
            let mut lo = [f64::INFINITY; 2];
            let mut hi = [f64::NEG_INFINITY; 2];
            for q in &pts {
                for k in 0..2 {
                    lo[k] = lo[k].min(q[k]);
                    hi[k] = hi[k].max(q[k]);
                }
            }
            if hi[0] <= 0.0 || hi[1] <= 0.0 || lo[0] >= w || lo[1] >= h {
                continue;
            }
            self.prims.push(Prim {
                tri: ti as u32,
                n: n as u8,
                sv: ids,
                lo,
                hi,
                normal,
                nd,
            });
        }
    }

    fn rows_of(&self, p: &Prim) -> std::ops::Range<usize> {
        let h = self.height as f64;
        let y0 = p.lo[1].max(0.0).floor() as usize;
        let y1 = p.hi[1].min(h).ceil() as usize;
        y0..y1.max(y0)
    }

    fn bin_rows(&mut self) {
        let h = self.height as usize;
        let mut count = vec![0u32; h + 1];
        for p in &self.prims {
            for y in self.rows_of(p) {
                count[y + 1] += 1;
            }
        }
        for y in 0..h {
            count[y + 1] += count[y];
        }
        let mut fill = count.clone();
        let mut list = vec![0u32; count[h] as usize];
        for (i, p) in self.prims.iter().enumerate() {
            for y in self.rows_of(p) {
                list[fill[y] as usize] = i as u32;
                fill[y] += 1;
            }
        }
        self.row_start = count;
        self.row_prims = list;
    }

    /// The x range `[x0, x1)` of pixels that prim `p` may touch in row `y`.
    fn columns(&self, p: &Prim, y: usize) -> (usize, usize) {
        let (y0, y1) = (y as f64, y as f64 + 1.0);
        let n = p.n as usize;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..n {
            let a = self.sv[p.sv[k] as usize];
            let b = self.sv[p.sv[(k + 1) % n] as usize];
            if a[1] >= y0 && a[1] <= y1 {
                lo = lo.min(a[0]);
                hi = hi.max(a[0]);
            }
            for yc in [y0, y1] {
                if (a[1] - yc) * (b[1] - yc) < 0.0 {
                    let x = a[0] + (b[0] - a[0]) * (yc - a[1]) / (b[1] - a[1]);
                    lo = lo.min(x);
                    hi = hi.max(x);
                }
            }
        }
        if !(lo <= hi) {
            return (0, 0);
        }
        let w = self.width as f64;
        let x0 = lo.max(0.0).floor() as usize;
        let x1 = (hi.min(w).floor() as usize + 1).min(self.width as usize);
        (x0, x1.max(x0))
    }

    /// Depth (distance along the optical axis) of prim `p`'s plane under screen point `q`.
    fn depth(&self, p: &Prim, q: [f64; 2]) -> f64 {
        let r = self.ray(q);
        p.nd / dot(p.normal, r)
    }

    /// Camera-space direction `(X, Y, −1)` through screen point `q`.
    #[inline]
    fn ray(&self, q: [f64; 2]) -> [f64; 3] {
        [
            (q[0] - self.cx) / self.fx,
            -(q[1] - self.cy) / self.fy,
            -1.0,
        ]
    }

    /// The visible pieces of every fragment of pixel `(x, y)`, given its candidate prims
    /// (in prim order): `(prim, pieces)` pairs.
    fn visible(&self, x: usize, y: usize, cands: &[u32], out: &mut Vec<(u32, Vec<Poly>)>) {
        out.clear();
        let (xf, yf) = (x as f64, y as f64);
        let corners = [
            [xf, yf],
            [xf + 1.0, yf],
            [xf + 1.0, yf + 1.0],
            [xf, yf + 1.0],
        ];
        let mut frags: Vec<(u32, Poly)> = Vec::with_capacity(cands.len());
        let mut tmp = Poly::new();
        for &pi in cands {
            let p = &self.prims[pi as usize];
            let mut poly = geom::pixel_box(xf, yf);
            let mut all_in = true;
            let mut empty = false;
            for e in p.edges() {
                let (a, b) = match e {
                    Line::Edge(a, b) => (self.sv[a as usize], self.sv[b as usize]),
                    _ => unreachable!(),
                };
                let side =
                    |q: [f64; 2]| (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]);
                let s = corners.map(side);
                if s.iter().all(|&v| v <= 0.0) {
                    empty = true;
                    break;
                }
                if s.iter().all(|&v| v >= 0.0) {
                    continue;
                }
                all_in = false;
                geom::clip(&poly, e, 1.0, &self.sv, &mut tmp);
                std::mem::swap(&mut poly, &mut tmp);
            }
            if empty || (!all_in && !(geom::area(&poly) > 0.0)) {
                continue;
            }
            frags.push((pi, poly));
        }
        let k = frags.len();
        if k == 1 {
            let (pi, poly) = frags.pop().expect("one fragment");
            out.push((pi, vec![poly]));
            return;
        }
        // occludes[i * k + j]: fragment j is in front of fragment i on their overlap.
        let mut occludes = vec![false; k * k];
        let mut overlap = Poly::new();
        for i in 0..k {
            for j in i + 1..k {
                let (pi, pj) = (
                    &self.prims[frags[i].0 as usize],
                    &self.prims[frags[j].0 as usize],
                );
                // Disjoint when one polygon lies outside an edge of the other (the common
                // case of neighbours in a mesh): a separating line, up to a hair of
                // round-off along a shared edge.
                if self.separated(pj, &frags[i].1) || self.separated(pi, &frags[j].1) {
                    continue;
                }
                overlap.clone_from(&frags[i].1);
                for e in pj.edges() {
                    geom::clip(&overlap, e, 1.0, &self.sv, &mut tmp);
                    std::mem::swap(&mut overlap, &mut tmp);
                    if overlap.len() < 3 {
                        break;
                    }
                }
                if !(geom::area(&overlap) > MIN_OVERLAP) {
                    continue;
                }
                let Some(c) = geom::centroid(&overlap) else {
                    continue;
                };
                let (di, dj) = (self.depth(pi, c), self.depth(pj, c));
                // Ties go to the earlier triangle (the lower index).
                if dj < di {
                    occludes[i * k + j] = true;
                } else {
                    occludes[j * k + i] = true;
                }
            }
        }
        for i in 0..k {
            let mut pieces = vec![frags[i].1.clone()];
            for j in 0..k {
                if !occludes[i * k + j] || pieces.is_empty() {
                    continue;
                }
                let edges: Vec<Line> = self.prims[frags[j].0 as usize].edges().collect();
                let mut next = Vec::with_capacity(pieces.len() + 2);
                for piece in &pieces {
                    geom::subtract(piece, &edges, &self.sv, &mut next, 0.0);
                }
                pieces = next;
            }
            if !pieces.is_empty() {
                out.push((frags[i].0, pieces));
            }
        }
    }

    /// Whether every vertex of `poly` is outside (or within 10⁻⁹ px of) one edge of `p`.
    fn separated(&self, p: &Prim, poly: &[geom::Vertex]) -> bool {
        let n = p.n as usize;
        (0..n).any(|k| {
            let a = self.sv[p.sv[k] as usize];
            let b = self.sv[p.sv[(k + 1) % n] as usize];
            let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
            let tol = 1e-9 * (ex.abs() + ey.abs());
            poly.iter()
                .all(|v| ex * (v.p[1] - a[1]) - ey * (v.p[0] - a[0]) <= tol)
        })
    }

    /// Perspective-correct barycentrics of triangle `tri` under screen point `q`, clamped
    /// into the triangle; also the raw `c_i = r · (P_j × P_k)`, their sign, and the sum of
    /// the clamped values (0 when degenerate).
    fn bary(&self, tri: [u32; 3], q: [f64; 2]) -> Bary {
        let r = self.ray(q);
        let p = tri.map(|i| self.pc[i as usize]);
        let c = [
            dot(r, cross(p[1], p[2])),
            dot(r, cross(p[2], p[0])),
            dot(r, cross(p[0], p[1])),
        ];
        let s = c[0] + c[1] + c[2];
        let sign = if s < 0.0 { -1.0 } else { 1.0 };
        let m = c.map(|v| (v * sign).max(0.0));
        let sum = m[0] + m[1] + m[2];
        let b = if sum > 0.0 && sum.is_finite() {
            m.map(|v| v / sum)
        } else {
            [1.0 / 3.0; 3]
        };
        Bary { b, m, sum, sign, r }
    }

    /// Color of triangle `tri` at the center of pixel `(x, y)` (straight RGB).
    fn shade(&self, tri: [u32; 3], q: [f64; 2]) -> ([f64; 3], Bary) {
        let bary = self.bary(tri, q);
        let b = bary.b;
        let mesh = self.mesh;
        let mut col = [1.0; 3];
        if let Some(vc) = &mesh.colors {
            col = [0.0; 3];
            for k in 0..3 {
                axpy(&mut col, b[k], vc[tri[k] as usize]);
            }
        }
        if let (Some(tex), Some(uvs)) = (&mesh.texture, &mesh.uvs) {
            let uv = uv_at(uvs, tri, b);
            let t = sample(tex, uv).0;
            for c in 0..3 {
                col[c] *= t[c];
            }
        }
        (col, bary)
    }

    /// Renders pixel `(x, y)`; with `grad = Some((g, sink))`, `g = ∂L/∂pixel`
    /// (premultiplied RGBA), adds the pixel's contributions into `sink`.
    fn pixel(
        &self,
        x: usize,
        y: usize,
        cands: &[u32],
        vis: &mut Vec<(u32, Vec<Poly>)>,
        grad: Option<([f32; 4], &mut RowSink)>,
    ) -> [f64; 4] {
        let bg = self.opts.background;
        if cands.is_empty() {
            return background_px(bg);
        }
        self.visible(x, y, cands, vis);
        let q = [x as f64 + 0.5, y as f64 + 0.5];
        let mut rgb = [0.0f64; 3];
        let mut cover = 0.0f64;
        let mut shaded = Vec::with_capacity(vis.len());
        for (pi, pieces) in vis.iter() {
            let a: f64 = pieces.iter().map(|p| geom::area(p)).sum();
            let tri = self.mesh.triangles[self.prims[*pi as usize].tri as usize];
            let (col, bary) = self.shade(tri, q);
            axpy(&mut rgb, a, col);
            cover += a;
            shaded.push((a, col, bary));
        }
        let alpha = match bg {
            Some(b) => {
                axpy(&mut rgb, 1.0 - cover, b);
                1.0
            }
            None => cover,
        };
        if let Some((g, sink)) = grad {
            let g = g.map(|v| v as f64);
            let bgc = bg.unwrap_or([0.0; 3]);
            for ((pi, pieces), (a, col, bary)) in vis.iter().zip(&shaded) {
                // ∂L/∂a = Σ_c g_c (col_c − bg_c) (+ g_α without a background).
                let mut ga = (0..3).map(|c| g[c] * (col[c] - bgc[c])).sum::<f64>();
                if bg.is_none() {
                    ga += g[3];
                }
                for p in pieces {
                    geom::area_backward(p, ga, &self.sv, sink);
                }
                let gcol = [g[0] * a, g[1] * a, g[2] * a];
                let tri = self.mesh.triangles[self.prims[*pi as usize].tri as usize];
                self.shade_backward(tri, bary, gcol, sink);
            }
        }
        [rgb[0], rgb[1], rgb[2], alpha]
    }

    fn shade_backward(&self, tri: [u32; 3], bary: &Bary, gcol: [f64; 3], sink: &mut RowSink) {
        let mesh = self.mesh;
        let b = bary.b;
        let mut base = [1.0; 3];
        if let Some(vc) = &mesh.colors {
            base = [0.0; 3];
            for k in 0..3 {
                axpy(&mut base, b[k], vc[tri[k] as usize]);
            }
        }
        let mut t = [1.0; 3];
        let mut gb = [0.0f64; 3];
        if let (Some(tex), Some(uvs)) = (&mesh.texture, &mesh.uvs) {
            let uv = uv_at(uvs, tri, b);
            let (tv, taps, duv) = sample(tex, uv);
            t = tv;
            let gt = [gcol[0] * base[0], gcol[1] * base[1], gcol[2] * base[2]];
            if sink.texels {
                for (idx, w) in taps {
                    sink.texel.push((idx, gt.map(|v| v * w)));
                }
            }
            // ∂L/∂uv, then ∂uv/∂b_k = uv_k.
            let mut guv = [0.0; 2];
            for c in 0..3 {
                guv[0] += gt[c] * duv[c][0];
                guv[1] += gt[c] * duv[c][1];
            }
            for k in 0..3 {
                let uvk = uvs[tri[k] as usize];
                gb[k] += guv[0] * uvk[0] + guv[1] * uvk[1];
            }
        }
        let gbase = [gcol[0] * t[0], gcol[1] * t[1], gcol[2] * t[2]];
        if let Some(vc) = &mesh.colors {
            for k in 0..3 {
                sink.color.push((tri[k], gbase.map(|v| v * b[k])));
                gb[k] += dot(gbase, vc[tri[k] as usize]);
            }
        }
        if !(bary.sum > 0.0 && bary.sum.is_finite()) || gb == [0.0; 3] {
            return;
        }
        // b = m / Σm: ∂b_i/∂m_j = (δ_ij − b_i) / Σm.
        let gb_dot_b = gb[0] * b[0] + gb[1] * b[1] + gb[2] * b[2];
        let p = tri.map(|i| self.pc[i as usize]);
        let r = bary.r;
        let mut gp = [[0.0f64; 3]; 3];
        for i in 0..3 {
            if bary.m[i] <= 0.0 {
                continue;
            }
            let gc = (gb[i] - gb_dot_b) / bary.sum * bary.sign;
            // c_i = r · (P_j × P_k): ∂c_i/∂P_j = P_k × r, ∂c_i/∂P_k = r × P_j.
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            axpy(&mut gp[j], gc, cross(p[k], r));
            axpy(&mut gp[k], gc, cross(r, p[j]));
        }
        for k in 0..3 {
            sink.cam.push((tri[k], gp[k]));
        }
    }

    /// Renders the image (premultiplied RGBA, see [`crate::mesh`]).
    pub fn render(&self) -> Image {
        let data = self.render_f64();
        Image {
            width: self.width,
            height: self.height,
            data: data.iter().map(|p| p.map(|v| v as f32)).collect(),
        }
    }

    /// The image in `f64` (what the gradient is the exact derivative of).
    pub(crate) fn render_f64(&self) -> Vec<[f64; 4]> {
        let w = self.width as usize;
        let mut data = vec![[0.0f64; 4]; w * self.height as usize];
        data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let mut vis = Vec::new();
            self.row(y, |x, cands| {
                row[x] = self.pixel(x, y, cands, &mut vis, None);
            });
        });
        data
    }

    /// Calls `f(x, candidates)` for every pixel of row `y`, candidates in prim order.
    fn row(&self, y: usize, mut f: impl FnMut(usize, &[u32])) {
        let w = self.width as usize;
        let list = &self.row_prims[self.row_start[y] as usize..self.row_start[y + 1] as usize];
        let mut count = vec![0u32; w + 1];
        let mut spans = Vec::with_capacity(list.len());
        for &pi in list {
            let (x0, x1) = self.columns(&self.prims[pi as usize], y);
            spans.push((x0, x1));
            for x in x0..x1 {
                count[x + 1] += 1;
            }
        }
        for x in 0..w {
            count[x + 1] += count[x];
        }
        let mut fill = count.clone();
        let mut cands = vec![0u32; count[w] as usize];
        for (&pi, &(x0, x1)) in list.iter().zip(&spans) {
            for x in x0..x1 {
                cands[fill[x] as usize] = pi;
                fill[x] += 1;
            }
        }
        for x in 0..w {
            f(x, &cands[count[x] as usize..count[x + 1] as usize]);
        }
    }

    /// The gradient of a loss with respect to the mesh, given `d_img = ∂L/∂image`
    /// (premultiplied RGBA, the size of the view). Texel gradients are collected only
    /// when `texels` is true.
    pub fn backward(&self, d_img: &Image, texels: bool) -> Result<MeshGrad> {
        if (d_img.width, d_img.height) != (self.width, self.height) {
            return Err(Error::Setting {
                name: "d_img".into(),
                message: format!(
                    "is {}×{}, the view is {}×{}",
                    d_img.width, d_img.height, self.width, self.height
                ),
            });
        }
        let w = self.width as usize;
        let rows: Vec<RowSink> = (0..self.height as usize)
            .into_par_iter()
            .map(|y| {
                let mut sink = RowSink {
                    texels,
                    ..RowSink::default()
                };
                let mut vis = Vec::new();
                self.row(y, |x, cands| {
                    let g = d_img.data[y * w + x];
                    if g != [0.0; 4] {
                        self.pixel(x, y, cands, &mut vis, Some((g, &mut sink)));
                    }
                });
                sink
            })
            .collect();
        let mesh = self.mesh;
        let mut gsv = vec![[0.0f64; 2]; self.sv.len()];
        let mut gcam = vec![[0.0f64; 3]; self.pc.len()];
        let mut gcol = mesh.colors.as_ref().map(|c| vec![[0.0f64; 3]; c.len()]);
        let mut gtex = match (&mesh.texture, texels) {
            (Some(t), true) => Some(vec![[0.0f64; 3]; t.data.len()]),
            _ => None,
        };
        for r in &rows {
            for &(i, g) in &r.sv {
                gsv[i as usize][0] += g[0];
                gsv[i as usize][1] += g[1];
            }
            for &(i, g) in &r.cam {
                axpy(&mut gcam[i as usize], 1.0, g);
            }
            if let Some(gc) = &mut gcol {
                for &(i, g) in &r.color {
                    axpy(&mut gc[i as usize], 1.0, g);
                }
            }
            if let Some(gt) = &mut gtex {
                for &(i, g) in &r.texel {
                    axpy(&mut gt[i as usize], 1.0, g);
                }
            }
        }
        drop(rows);
        // Screen vertices back to camera space.
        for (s, g) in self.src.iter().zip(&gsv) {
            if *g == [0.0; 2] {
                continue;
            }
            match *s {
                Src::Vert(i) => {
                    let p = self.pc[i as usize];
                    axpy(&mut gcam[i as usize], 1.0, self.project_backward(p, *g));
                }
                Src::Clip(a, b) => {
                    let q = self.clip_point(a, b);
                    let gq = self.project_backward(q, *g);
                    let (pa, pb) = (self.pc[a as usize], self.pc[b as usize]);
                    let zn = -self.opts.near;
                    let den = pa[2] - pb[2];
                    let t = (pa[2] - zn) / den;
                    // q = pa + t (pb − pa) with q_z fixed at zn.
                    let gt = gq[0] * (pb[0] - pa[0]) + gq[1] * (pb[1] - pa[1]);
                    let dt_dza = (zn - pb[2]) / (den * den);
                    let dt_dzb = (pa[2] - zn) / (den * den);
                    let ga = [(1.0 - t) * gq[0], (1.0 - t) * gq[1], gt * dt_dza];
                    let gb = [t * gq[0], t * gq[1], gt * dt_dzb];
                    axpy(&mut gcam[a as usize], 1.0, ga);
                    axpy(&mut gcam[b as usize], 1.0, gb);
                }
            }
        }
        // Camera space P = R (p − eye): ∂L/∂p = Rᵀ ∂L/∂P.
        let rot = self.rot;
        let positions = gcam
            .iter()
            .map(|g| {
                let mut o = [0.0; 3];
                for k in 0..3 {
                    axpy(&mut o, g[k], rot[k]);
                }
                o
            })
            .collect();
        Ok(MeshGrad {
            positions,
            colors: gcol,
            texture: gtex,
        })
    }

    /// `∂L/∂P` of a camera-space point from `∂L/∂(x, y)` of its projection.
    fn project_backward(&self, p: [f64; 3], g: [f64; 2]) -> [f64; 3] {
        // x = cx − fx X / Z, y = cy + fy Y / Z.
        let (x, y, z) = (p[0], p[1], p[2]);
        [
            -g[0] * self.fx / z,
            g[1] * self.fy / z,
            g[0] * self.fx * x / (z * z) - g[1] * self.fy * y / (z * z),
        ]
    }

    /// Number of triangles that survived culling and clipping (and touch the image).
    pub fn visible_triangles(&self) -> usize {
        self.prims.len()
    }
}

/// Perspective-correct barycentrics and what their backward pass needs.
#[derive(Clone, Copy, Debug)]
struct Bary {
    b: [f64; 3],
    m: [f64; 3],
    sum: f64,
    sign: f64,
    r: [f64; 3],
}

/// One row's gradient contributions, added in row order.
#[derive(Default)]
struct RowSink {
    texels: bool,
    sv: Vec<(u32, [f64; 2])>,
    cam: Vec<(u32, [f64; 3])>,
    color: Vec<(u32, [f64; 3])>,
    texel: Vec<(u32, [f64; 3])>,
}

impl GradSink for RowSink {
    fn add(&mut self, i: u32, g: [f64; 2]) {
        if g != [0.0; 2] {
            self.sv.push((i, g));
        }
    }
}

fn background_px(bg: Option<[f64; 3]>) -> [f64; 4] {
    match bg {
        Some(b) => [b[0], b[1], b[2], 1.0],
        None => [0.0; 4],
    }
}

fn uv_at(uvs: &[[f64; 2]], tri: [u32; 3], b: [f64; 3]) -> [f64; 2] {
    let mut uv = [0.0; 2];
    for k in 0..3 {
        let t = uvs[tri[k] as usize];
        uv[0] += b[k] * t[0];
        uv[1] += b[k] * t[1];
    }
    uv
}

/// A texture sample: the value, the four taps `(texel, weight)` and `∂value_c/∂(u, v)`.
type Sample = ([f64; 3], [(u32, f64); 4], [[f64; 2]; 3]);

/// Bilinear sample of `tex` at `uv` (repeat): the value, the four taps `(texel, weight)`
/// and `∂value_c/∂(u, v)`.
fn sample(tex: &Texture, uv: [f64; 2]) -> Sample {
    let (w, h) = (tex.width as f64, tex.height as f64);
    let tx = uv[0] * w - 0.5;
    let ty = (1.0 - uv[1]) * h - 0.5;
    let (x0, y0) = (tx.floor(), ty.floor());
    let (fx, fy) = (tx - x0, ty - y0);
    let wrap = |v: f64, n: u32| {
        if v >= 0.0 && v < n as f64 {
            v as u32
        } else {
            (v.rem_euclid(n as f64) as u32).min(n - 1)
        }
    };
    let (xa, xb) = (wrap(x0, tex.width), wrap(x0 + 1.0, tex.width));
    let (ya, yb) = (wrap(y0, tex.height), wrap(y0 + 1.0, tex.height));
    let idx = |x: u32, y: u32| y * tex.width + x;
    let taps = [
        (idx(xa, ya), (1.0 - fx) * (1.0 - fy)),
        (idx(xb, ya), fx * (1.0 - fy)),
        (idx(xa, yb), (1.0 - fx) * fy),
        (idx(xb, yb), fx * fy),
    ];
    let t = taps.map(|(i, _)| tex.data[i as usize]);
    let mut v = [0.0; 3];
    let mut d = [[0.0; 2]; 3];
    for c in 0..3 {
        v[c] = taps.iter().zip(&t).map(|((_, wt), tv)| wt * tv[c]).sum();
        let dtx = (1.0 - fy) * (t[1][c] - t[0][c]) + fy * (t[3][c] - t[2][c]);
        let dty = (1.0 - fx) * (t[2][c] - t[0][c]) + fx * (t[3][c] - t[1][c]);
        d[c] = [dtx * w, -dty * h];
    }
    (v, taps, d)
}

/// Renders `mesh` through `camera` (see [`crate::mesh`] for the conventions).
pub fn render(mesh: &Mesh, camera: &Camera, opts: &RenderOptions) -> Result<Image> {
    Ok(View::new(mesh, camera, *opts)?.render())
}

/// The gradient of a loss with respect to `mesh` given `d_img = ∂L/∂image` for the image
/// [`render`] gives; texel gradients included when the mesh has a texture.
pub fn render_backward(
    mesh: &Mesh,
    camera: &Camera,
    opts: &RenderOptions,
    d_img: &Image,
) -> Result<MeshGrad> {
    View::new(mesh, camera, *opts)?.backward(d_img, true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn camera(w: u32, h: u32) -> Camera {
        Camera::look_at(Vec3::new(0.3, 0.2, 3.0), Vec3::ZERO, Vec3::Y, 0.5, w, h).unwrap()
    }

    /// Triangles with their own (unshared) vertices and a flat color each.
    fn soup(tris: &[[[f64; 3]; 3]], colors: &[[f64; 3]]) -> Mesh {
        let mut m = Mesh {
            positions: Vec::new(),
            triangles: Vec::new(),
            uvs: None,
            colors: Some(Vec::new()),
            texture: None,
        };
        for (t, c) in tris.iter().zip(colors) {
            let b = m.positions.len() as u32;
            m.positions.extend_from_slice(t);
            m.colors.as_mut().unwrap().extend([*c; 3]);
            m.triangles.push([b, b + 1, b + 2]);
        }
        m
    }

    /// A fixed pseudo-random weight image, exactly representable in f32.
    fn weights(w: u32, h: u32) -> Image {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let data = (0..w * h)
            .map(|_| {
                [0; 4].map(|_| {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    ((s >> 40) as f32 / (1u64 << 24) as f32) - 0.5
                })
            })
            .collect();
        Image {
            width: w,
            height: h,
            data,
        }
    }

    fn loss(mesh: &Mesh, cam: &Camera, opts: RenderOptions, wts: &Image) -> f64 {
        let img = View::new(mesh, cam, opts).unwrap().render_f64();
        img.iter()
            .zip(&wts.data)
            .map(|(p, w)| (0..4).map(|c| p[c] * w[c] as f64).sum::<f64>())
            .sum()
    }

    /// Checks every position and color gradient against central differences.
    fn check(name: &str, mesh: &Mesh, opts: RenderOptions) {
        let cam = camera(12, 10);
        let wts = weights(12, 10);
        let g = View::new(mesh, &cam, opts)
            .unwrap()
            .backward(&wts, true)
            .unwrap();
        // Small steps: pieces whose vertices are crossings of nearly parallel lines have
        // large second derivatives (at 1e-6 a fold's central difference is off by 2e-5).
        let h = 1e-7;
        let mut nonzero = 0;
        for v in 0..mesh.positions.len() {
            for k in 0..3 {
                let (mut p, mut m) = (mesh.clone(), mesh.clone());
                p.positions[v][k] += h;
                m.positions[v][k] -= h;
                let fd = (loss(&p, &cam, opts, &wts) - loss(&m, &cam, opts, &wts)) / (2.0 * h);
                let an = g.positions[v][k];
                let err = (fd - an).abs() / an.abs().max(1.0);
                assert!(
                    err < 1e-5,
                    "{name}: vertex {v} axis {k}: analytic {an} vs fd {fd}"
                );
                if an.abs() > 1e-3 {
                    nonzero += 1;
                }
                if let (Some(gc), Some(_)) = (&g.colors, &mesh.colors) {
                    let (mut p, mut m) = (mesh.clone(), mesh.clone());
                    p.colors.as_mut().unwrap()[v][k] += h;
                    m.colors.as_mut().unwrap()[v][k] -= h;
                    let fd = (loss(&p, &cam, opts, &wts) - loss(&m, &cam, opts, &wts)) / (2.0 * h);
                    let an = gc[v][k];
                    assert!(
                        (fd - an).abs() < 1e-6 * an.abs().max(1.0),
                        "{name}: color {v}.{k}: {an} vs {fd}"
                    );
                }
            }
        }
        assert!(nonzero > 0, "{name}: every gradient is zero");
    }

    fn opts() -> RenderOptions {
        RenderOptions {
            background: Some([0.2, 0.3, 0.4]),
            cull_back_faces: false,
            near: 1e-3,
        }
    }

    #[test]
    fn gradients_match_differences_interior_and_silhouette() {
        // One big triangle with smooth vertex colors: interior (colors through the
        // perspective-correct barycentrics) and silhouette edges on the background.
        let mut m = soup(
            &[[[-0.9, -0.6, 0.1], [0.8, -0.5, -0.3], [0.1, 0.7, 0.2]]],
            &[[0.0; 3]],
        );
        m.colors = Some(vec![[1.0, 0.1, 0.2], [0.1, 0.9, 0.3], [0.2, 0.3, 1.0]]);
        check("interior+silhouette", &m, opts());
        check(
            "transparent",
            &m,
            RenderOptions {
                background: None,
                ..opts()
            },
        );
    }

    #[test]
    fn gradients_match_differences_at_occlusion_edges_and_folds() {
        // A front triangle partly over a back one (occlusion edge), and two triangles
        // sharing an edge folded so that one hides part of the other.
        let occl = soup(
            &[
                [[-0.8, -0.7, -0.4], [0.9, -0.6, -0.5], [0.0, 0.8, -0.6]],
                [[-0.3, -0.2, 0.4], [0.5, 0.1, 0.3], [-0.1, 0.6, 0.5]],
            ],
            &[[0.9, 0.2, 0.1], [0.1, 0.3, 0.9]],
        );
        check("occlusion", &occl, opts());
        let mut fold = Mesh {
            positions: vec![
                [-0.7, -0.5, 0.0],
                [0.6, -0.4, 0.1],
                [0.0, 0.6, 0.0],
                [-0.2, 0.1, 0.9],
            ],
            triangles: vec![[0, 1, 2], [0, 1, 3]],
            uvs: None,
            colors: Some(vec![
                [0.9, 0.1, 0.1],
                [0.1, 0.9, 0.1],
                [0.1, 0.1, 0.9],
                [0.9, 0.9, 0.1],
            ]),
            texture: None,
        };
        check("fold", &fold, opts());
        fold.colors = None;
        check("fold, white", &fold, opts());
    }

    #[test]
    fn gradients_match_differences_for_sub_pixel_and_near_clipped_triangles() {
        // About a third of a pixel wide at this distance (the image is 12 px across
        // 0.5 rad at 3 units: 1 px ≈ 0.125 units).
        let tiny = soup(
            &[[[0.02, 0.01, 0.0], [0.06, 0.015, 0.0], [0.035, 0.05, 0.01]]],
            &[[0.9, 0.5, 0.1]],
        );
        check("sub-pixel", &tiny, opts());
        // A triangle crossing the near plane (the camera sits at z ≈ 3).
        let near = RenderOptions {
            near: 0.5,
            ..opts()
        };
        let clipped = soup(
            &[[[-0.3, -0.2, 0.0], [0.4, -0.1, 0.2], [0.35, 0.35, 2.9]]],
            &[[0.3, 0.8, 0.4]],
        );
        assert!(
            View::new(&clipped, &camera(12, 10), near)
                .unwrap()
                .src
                .iter()
                .any(|s| matches!(s, Src::Clip(..)))
        );
        check("near-clipped", &clipped, near);
    }

    #[test]
    fn texture_gradients_match_differences() {
        let mut m = soup(
            &[[[-0.9, -0.6, 0.1], [0.8, -0.5, -0.3], [0.1, 0.7, 0.2]]],
            &[[0.0; 3]],
        );
        m.colors = None;
        m.uvs = Some(vec![[0.1, 0.2], [0.9, 0.1], [0.5, 0.95]]);
        m.texture = Some(Texture {
            width: 3,
            height: 2,
            data: (0..6)
                .map(|i| [0.1 * i as f64, 1.0 - 0.15 * i as f64, 0.5])
                .collect(),
        });
        let cam = camera(12, 10);
        let wts = weights(12, 10);
        let g = View::new(&m, &cam, opts())
            .unwrap()
            .backward(&wts, true)
            .unwrap();
        let gt = g.texture.unwrap();
        let h = 1e-6;
        for i in 0..6 {
            for c in 0..3 {
                let (mut p, mut q) = (m.clone(), m.clone());
                p.texture.as_mut().unwrap().data[i][c] += h;
                q.texture.as_mut().unwrap().data[i][c] -= h;
                let fd = (loss(&p, &cam, opts(), &wts) - loss(&q, &cam, opts(), &wts)) / (2.0 * h);
                assert!(
                    (fd - gt[i][c]).abs() < 1e-6,
                    "texel {i}.{c}: {} vs {fd}",
                    gt[i][c]
                );
            }
        }
        // Positions through the UVs (away from texel borders, the sample is smooth).
        check("textured", &m, opts());
    }

    #[test]
    fn same_bits_on_one_two_and_three_threads() {
        let mesh = super::super::icosphere(2, 0.8);
        let mut mesh = mesh;
        mesh.colors = Some(
            mesh.positions
                .iter()
                .map(|p| p.map(|v| 0.5 + 0.5 * v))
                .collect(),
        );
        let cam = camera(40, 32);
        let wts = weights(40, 32);
        let run = |n: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            pool.install(|| {
                let v = View::new(&mesh, &cam, RenderOptions::default()).unwrap();
                (v.render_f64(), v.backward(&wts, true).unwrap())
            })
        };
        let one = run(1);
        assert!(one.1.positions.iter().any(|g| g != &[0.0; 3]));
        for n in [2, 3] {
            let other = run(n);
            assert!(
                one.0
                    .iter()
                    .zip(&other.0)
                    .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits))
            );
            let bits = |g: &MeshGrad| {
                g.positions
                    .iter()
                    .chain(g.colors.as_ref().unwrap())
                    .flat_map(|v| v.map(f64::to_bits))
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&one.1), bits(&other.1), "{n} threads");
        }
    }

    /// The reference: `n × n` point samples per pixel, each taking the color of the
    /// nearest triangle whose projection contains it (or the background).
    fn supersampled(view: &View, n: usize) -> Vec<[f64; 4]> {
        let (w, h) = (view.width as usize, view.height as usize);
        let bg = view.opts.background.unwrap();
        let mut out = vec![[0.0; 4]; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0; 3];
                for sy in 0..n {
                    for sx in 0..n {
                        let q = [
                            x as f64 + (sx as f64 + 0.5) / n as f64,
                            y as f64 + (sy as f64 + 0.5) / n as f64,
                        ];
                        let mut best = (f64::INFINITY, bg);
                        for p in &view.prims {
                            let k = p.n as usize;
                            let inside = (0..k).all(|e| {
                                let (a, b) = (
                                    view.sv[p.sv[e] as usize],
                                    view.sv[p.sv[(e + 1) % k] as usize],
                                );
                                (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) >= 0.0
                            });
                            let d = view.depth(p, q);
                            if inside && d < best.0 {
                                let tri = view.mesh.triangles[p.tri as usize];
                                best = (d, view.mesh.colors.as_ref().unwrap()[tri[0] as usize]);
                            }
                        }
                        for c in 0..3 {
                            acc[c] += best.1[c];
                        }
                    }
                }
                let s = (n * n) as f64;
                out[y * w + x] = [acc[0] / s, acc[1] / s, acc[2] / s, 1.0];
            }
        }
        out
    }

    #[test]
    fn flat_scenes_match_a_supersampled_reference() {
        // Overlapping, non-interpenetrating triangles in depth, including a sub-pixel one
        // and a closed icosphere behind them.
        let mut m = soup(
            &[
                [[-0.8, -0.7, -0.4], [0.9, -0.6, -0.5], [0.0, 0.8, -0.6]],
                [[-0.3, -0.2, 0.4], [0.5, 0.1, 0.3], [-0.1, 0.6, 0.5]],
                [[0.02, 0.01, 0.8], [0.06, 0.015, 0.8], [0.035, 0.05, 0.81]],
            ],
            &[[0.9, 0.2, 0.1], [0.1, 0.3, 0.9], [1.0, 1.0, 0.0]],
        );
        let ball = super::super::icosphere(1, 0.4);
        let base = m.positions.len() as u32;
        m.positions.extend(
            ball.positions
                .iter()
                .map(|p| [p[0] - 0.4, p[1] + 0.2, p[2] - 1.2]),
        );
        m.colors
            .as_mut()
            .unwrap()
            .extend(ball.positions.iter().map(|_| [0.2, 0.9, 0.3]));
        // Flat per triangle: give each ball triangle its own vertices' color (all equal).
        m.triangles
            .extend(ball.triangles.iter().map(|t| t.map(|i| i + base)));
        let cam = camera(16, 12);
        for cull in [false, true] {
            let o = RenderOptions {
                cull_back_faces: cull,
                ..opts()
            };
            let view = View::new(&m, &cam, o).unwrap();
            let img = view.render_f64();
            let n = 64;
            let reference = supersampled(&view, n);
            let mut worst = 0.0f64;
            for (a, b) in img.iter().zip(&reference) {
                for c in 0..3 {
                    worst = worst.max((a[c] - b[c]).abs());
                }
            }
            // Point sampling errs by at most one sample row per edge crossing: n / n² of
            // the pixel per edge, times the largest color step (< 1).
            eprintln!("cull {cull}: max error against {n}×{n} samples: {worst:.2e}");
            // The bound: half a level of 8 bits.
            assert!(worst < 0.5 / 255.0, "cull {cull}: max error {worst}");
            assert!(worst > 0.0);
        }
    }

    #[test]
    fn interpenetrating_triangles_never_cover_more_than_the_pixel() {
        // Two triangles crossing each other (a "+" seen from above): inside a pixel where
        // they cross, the nearer at the overlap's centroid takes the whole overlap.
        let m = soup(
            &[
                [[-0.8, -0.6, -0.5], [0.8, -0.6, 0.5], [0.0, 0.7, 0.0]],
                [[-0.8, -0.6, 0.5], [0.8, -0.6, -0.5], [0.0, 0.7, 0.0]],
            ],
            &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        );
        let cam = camera(16, 12);
        let o = RenderOptions {
            background: None,
            ..opts()
        };
        let view = View::new(&m, &cam, o).unwrap();
        let img = view.render_f64();
        let (mut red, mut green) = (0, 0);
        for p in &img {
            assert!(p[3] <= 1.0 + 1e-12, "coverage {}", p[3]);
            assert!((p[0] + p[1] - p[3]).abs() < 1e-12);
            // A fully covered pixel is all one triangle: the crossing is not resolved
            // inside a pixel.
            if p[3] > 1.0 - 1e-9 {
                assert!(p[0] > 1.0 - 1e-9 || p[1] > 1.0 - 1e-9, "{p:?}");
                red += (p[0] > 0.5) as usize;
                green += (p[1] > 0.5) as usize;
            }
        }
        // Each triangle is in front on its own side of the crossing line.
        assert!(red > 5 && green > 5, "{red} red, {green} green");
        let interior = red + green;
        assert!(interior > 10);
    }
}
