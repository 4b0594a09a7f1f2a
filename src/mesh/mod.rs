//! Triangle meshes rendered with the **exact visible area** of every triangle in every
//! pixel, and the exact gradient of that image.
//!
//! # Conventions
//!
//! * **World and cameras**: [`crate::volume::camera::Camera`] (OpenGL camera axes: +X right,
//!   +Y up, looking down −Z; pixel `(x, y)` covers `[x, x+1] × [y, y+1]`, y down).
//!   Cameras with lens distortion are refused (straight edges must stay straight).
//! * **Triangles**: counter-clockwise seen from the front (OBJ's convention); with
//!   [`RenderOptions::cull_back_faces`] a triangle seen from behind is skipped.
//! * **Pixels**: each pixel is the box filter of the scene: `Σ_t a_t · c_t + (1 − Σ_t a_t)
//!   · background`, where `a_t` is the area of triangle `t` visible in the pixel (front
//!   triangles occlude back ones *by area*, not by a depth test at the pixel center) and
//!   `c_t` is the triangle's color at the pixel center: perspective-correct barycentrics
//!   of the ray through `(x + ½, y + ½)`, clamped into the triangle (negative ones set to
//!   zero and the rest renormalized), interpolating vertex colors (white when the mesh
//!   has none) multiplied by the bilinearly sampled texture. This is the 2D
//!   rasterizer's contract (exact coverage, paint at the pixel center).
//! * **Interpenetration**: where two triangles cross *inside* a pixel, the one nearer at
//!   the centroid of their overlap in that pixel occludes the other over the whole
//!   overlap; the error is at most the overlap's area, and the covered total never
//!   exceeds 1 (see the tests in `render.rs`).
//! * **Near plane**: triangles are clipped against the plane at depth
//!   [`RenderOptions::near`] (world units in front of the camera) before projection.
//! * **Images**: [`Image`] is premultiplied RGBA; without a background alpha is the
//!   covered fraction, with one every pixel is opaque.
//! * **Texture**: straight RGB in `[0, 1]`, `(u, v)` with v up (OBJ), repeated outside
//!   `[0, 1]`, bilinear between texel centers; no mip levels yet.
//! * **Shading**: unlit by default (the color is the albedo: vertex colors times
//!   texture); with [`RenderOptions::lighting`] Lambert shading by an ambient term and
//!   directional lights with smooth (area-weighted, interpolated) normals ([`Lighting`]).
//!   The backward pass also gives the gradient of the UVs, the lights and the camera
//!   pose ([`MeshGrad`]).

pub mod fit;
mod geom;
mod gltf;
mod io;
pub mod refine;
pub mod render;
mod shapes;
pub mod simplify;

pub use gltf::{read_gltf, write_gltf};
pub use io::{MeshFormat, read_mesh, read_obj, write_mesh, write_obj};
pub use render::{
    DirLight, Lighting, LightingGrad, MAX_LIGHTS, MeshGrad, MipPyramid, RenderOptions, View,
    render, render_backward,
};
pub use shapes::{icosphere, octahedron, torus_knot};

use crate::Image;

/// An RGB texture, straight values in `[0, 1]`, row-major with row 0 at the top (v = 1).
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width × height` texels.
    pub data: Vec<[f64; 3]>,
}

impl Texture {
    /// The texture of an image's colors (premultiplied colors over black).
    pub fn from_image(img: &Image) -> Texture {
        Texture {
            width: img.width,
            height: img.height,
            data: img
                .data
                .iter()
                .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64])
                .collect(),
        }
    }

    /// As an opaque image.
    pub fn to_image(&self) -> Image {
        Image {
            width: self.width,
            height: self.height,
            data: self
                .data
                .iter()
                .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32, 1.0])
                .collect(),
        }
    }
}

/// A triangle mesh: positions, triangles, and optional per-vertex UVs and colors and a
/// texture. Attributes are per vertex (an OBJ vertex used with two UVs is split).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions, world units.
    pub positions: Vec<[f64; 3]>,
    /// Triangles as counter-clockwise (front) vertex indices.
    pub triangles: Vec<[u32; 3]>,
    /// Texture coordinates `(u, v)` per vertex, v up; required with a texture.
    pub uvs: Option<Vec<[f64; 2]>>,
    /// Straight RGB colors in `[0, 1]` per vertex.
    pub colors: Option<Vec<[f64; 3]>>,
    /// The texture, multiplied with the vertex colors.
    pub texture: Option<Texture>,
}

impl Mesh {
    /// Checks indices, attribute lengths and finiteness; `what` names the mesh in errors.
    pub fn validate(&self, what: &std::path::Path) -> crate::Result<()> {
        let bad = |what_: String| crate::Error::InvalidValue {
            path: what.to_path_buf(),
            what: what_,
        };
        let n = self.positions.len();
        if n > crate::limits::MAX_MESH_VERTICES {
            return Err(bad(format!(
                "{n} vertices exceed the limit of {}",
                crate::limits::MAX_MESH_VERTICES
            )));
        }
        if self.triangles.len() > crate::limits::MAX_MESH_TRIANGLES {
            return Err(bad(format!(
                "{} triangles exceed the limit of {}",
                self.triangles.len(),
                crate::limits::MAX_MESH_TRIANGLES
            )));
        }
        if let Some(i) = self
            .positions
            .iter()
            .position(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(bad(format!("vertex {i} has a non-finite coordinate")));
        }
        if let Some((t, _)) = self
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= n))
        {
            return Err(bad(format!(
                "triangle {t} names a vertex past the {n} vertices"
            )));
        }
        if let Some(uv) = &self.uvs {
            if uv.len() != n {
                return Err(bad(format!("{} UVs for {n} vertices", uv.len())));
            }
            if uv.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
                return Err(bad("a UV is not finite".into()));
            }
        }
        if let Some(c) = &self.colors {
            if c.len() != n {
                return Err(bad(format!("{} colors for {n} vertices", c.len())));
            }
            if c.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
                return Err(bad("a vertex color is not finite".into()));
            }
        }
        if let Some(t) = &self.texture {
            if self.uvs.is_none() {
                return Err(bad("a texture without UVs".into()));
            }
            if t.width == 0 || t.height == 0 || t.data.len() != t.width as usize * t.height as usize
            {
                return Err(bad(format!(
                    "texture {}×{} holds {} texels",
                    t.width,
                    t.height,
                    t.data.len()
                )));
            }
        }
        Ok(())
    }

    /// The axis-aligned bounds `(min, max)` of the positions (zeros when empty).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        if self.positions.is_empty() {
            return ([0.0; 3], [0.0; 3]);
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }
}
