//! Wavefront OBJ (+ MTL + texture) reading through `tobj`, and writing.

use std::path::{Path, PathBuf};

use super::{Mesh, Texture};
use crate::Image;
use crate::error::{Error, Result};
use crate::image_io::{read_bounded, write_atomic};
use crate::limits::{MAX_MESH_FILE_BYTES, MAX_MESH_TRIANGLES, MAX_MESH_VERTICES};

pub(super) fn invalid(path: &Path, what: impl Into<String>) -> Error {
    Error::InvalidValue {
        path: path.to_path_buf(),
        what: what.into(),
    }
}

/// A mesh file's format, by its extension (any case).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// `.obj` (with an MTL and a PNG beside it).
    Obj,
    /// `.gltf`: JSON with its buffers embedded.
    Gltf,
    /// `.glb`: binary glTF.
    Glb,
}

impl MeshFormat {
    /// The format `path`'s extension names, or `None` for another extension.
    pub fn of(path: &Path) -> Option<MeshFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Some(MeshFormat::Obj),
            "gltf" => Some(MeshFormat::Gltf),
            "glb" => Some(MeshFormat::Glb),
            _ => None,
        }
    }

    /// The extension, lowercase, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            MeshFormat::Obj => "obj",
            MeshFormat::Gltf => "gltf",
            MeshFormat::Glb => "glb",
        }
    }
}

/// Reads a mesh by its file's extension: glTF (`.gltf`, `.glb`, [`read_gltf`](super::read_gltf))
/// or otherwise OBJ ([`read_obj`]).
pub fn read_mesh(path: &Path) -> Result<Mesh> {
    match MeshFormat::of(path) {
        Some(MeshFormat::Gltf | MeshFormat::Glb) => super::read_gltf(path),
        _ => read_obj(path),
    }
}

/// Counts `v`, `vt` and fanned `f` triangles in an OBJ's text, to refuse a file past the
/// limits before the parser allocates.
fn count_obj(text: &str) -> (usize, usize) {
    let (mut v, mut t) = (0usize, 0usize);
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => v += 1,
            Some("f") => t += it.count().saturating_sub(2),
            _ => {}
        }
    }
    (v, t)
}

/// Reads an OBJ mesh with its vertex colors (`v x y z r g b`), or else its MTL
/// material's diffuse color, and its diffuse texture (the first material used; one
/// texture per mesh). All objects of the file are merged.
/// Polygons are fanned into triangles; a vertex used with several UVs is split.
///
/// Sizes are checked before anything is parsed ([`MAX_MESH_FILE_BYTES`] per file,
/// [`MAX_MESH_VERTICES`], [`MAX_MESH_TRIANGLES`] counted in the text) and the texture's
/// header before it is decoded; every error names the file.
pub fn read_obj(path: &Path) -> Result<Mesh> {
    let bytes = read_bounded(path, MAX_MESH_FILE_BYTES)?;
    let text =
        std::str::from_utf8(&bytes).map_err(|e| invalid(path, format!("not UTF-8 text: {e}")))?;
    let (nv, nt) = count_obj(text);
    if nv > MAX_MESH_VERTICES {
        return Err(invalid(
            path,
            format!("{nv} vertices exceed the limit of {MAX_MESH_VERTICES}"),
        ));
    }
    if nt > MAX_MESH_TRIANGLES {
        return Err(invalid(
            path,
            format!("{nt} triangles exceed the limit of {MAX_MESH_TRIANGLES}"),
        ));
    }
    if nt == 0 {
        return Err(invalid(path, "no faces"));
    }
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mtl_error: std::cell::RefCell<Option<Error>> = std::cell::RefCell::new(None);
    let opts = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, materials) = tobj::load_obj_buf(
        &mut std::io::Cursor::new(&bytes[..]),
        &opts,
        |mtl: &Path| {
            let p = dir.join(mtl);
            match read_bounded(&p, MAX_MESH_FILE_BYTES) {
                Ok(b) => tobj::load_mtl_buf(&mut std::io::Cursor::new(&b[..])).inspect_err(|e| {
                    *mtl_error.borrow_mut() = Some(invalid(&p, format!("malformed MTL: {e}")));
                }),
                Err(e) => {
                    *mtl_error.borrow_mut() = Some(e);
                    Err(tobj::LoadError::OpenFileFailed)
                }
            }
        },
    )
    .map_err(|e| invalid(path, format!("malformed OBJ: {e}")))?;
    if let Some(e) = mtl_error.into_inner() {
        return Err(e);
    }
    let materials = materials.unwrap_or_default();
    let mut mesh = Mesh::default();
    let all_uv = models.iter().all(|m| !m.mesh.texcoords.is_empty());
    let all_colors = models
        .iter()
        .all(|m| m.mesh.vertex_color.len() == m.mesh.positions.len());
    let mut colors = Vec::new();
    let mut uvs = Vec::new();
    let mut material = None;
    for m in &models {
        let mm = &m.mesh;
        let base = mesh.positions.len();
        let n = mm.positions.len() / 3;
        if base + n > MAX_MESH_VERTICES {
            return Err(invalid(
                path,
                format!("more than {MAX_MESH_VERTICES} vertices"),
            ));
        }
        mesh.positions.extend(
            mm.positions
                .chunks_exact(3)
                .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]),
        );
        if all_uv {
            if mm.texcoords.len() / 2 != n {
                return Err(invalid(
                    path,
                    format!(
                        "object {:?}: {} UVs for {n} vertices",
                        m.name,
                        mm.texcoords.len() / 2
                    ),
                ));
            }
            uvs.extend(
                mm.texcoords
                    .chunks_exact(2)
                    .map(|t| [t[0] as f64, t[1] as f64]),
            );
        }
        if all_colors {
            colors.extend(
                mm.vertex_color
                    .chunks_exact(3)
                    .map(|c| [c[0] as f64, c[1] as f64, c[2] as f64]),
            );
        }
        for t in mm.indices.chunks_exact(3) {
            if t.iter().any(|&i| i as usize >= n) {
                return Err(invalid(
                    path,
                    format!("object {:?}: a face names a missing vertex", m.name),
                ));
            }
            mesh.triangles
                .push([t[0] + base as u32, t[1] + base as u32, t[2] + base as u32]);
        }
        if material.is_none() {
            material = mm.material_id.and_then(|i| materials.get(i));
        }
    }
    if all_uv {
        mesh.uvs = Some(uvs);
    }
    // Vertex colors (`v x y z r g b`) win over a material's diffuse color.
    if all_colors && !colors.is_empty() {
        mesh.colors = Some(colors);
    }
    if let Some(mat) = material {
        if let Some(tex) = mat.diffuse_texture.as_ref().filter(|t| !t.is_empty()) {
            if mesh.uvs.is_none() {
                return Err(invalid(
                    path,
                    format!(
                        "material {:?} has a texture but the mesh has no UVs",
                        mat.name
                    ),
                ));
            }
            let tp = resolve(path, tex);
            let img = Image::load(&tp)?;
            mesh.texture = Some(Texture::from_image(&img));
        } else if let (Some(kd), None) = (mat.diffuse, &mesh.colors) {
            mesh.colors = Some(vec![
                [kd[0] as f64, kd[1] as f64, kd[2] as f64];
                mesh.positions.len()
            ]);
        }
    }
    mesh.validate(path)?;
    Ok(mesh)
}

/// A texture path of an MTL, relative to the OBJ's folder.
fn resolve(obj: &Path, tex: &str) -> PathBuf {
    let t = Path::new(tex.trim());
    if t.is_absolute() {
        t.to_path_buf()
    } else {
        obj.parent().unwrap_or(Path::new("")).join(t)
    }
}

/// Writes a mesh by its file's extension: glTF (`.gltf`, `.glb`,
/// [`write_gltf`](super::write_gltf)) or otherwise OBJ ([`write_obj`]).
pub fn write_mesh(mesh: &Mesh, path: &Path) -> Result<()> {
    match MeshFormat::of(path) {
        Some(MeshFormat::Gltf | MeshFormat::Glb) => super::write_gltf(mesh, path),
        _ => write_obj(mesh, path),
    }
}

/// Writes `mesh` as OBJ (positions, UVs, triangles) with, when it has colors or a
/// texture, an MTL beside it (`NAME.mtl`) and the texture as `NAME.png`. Vertex colors
/// are written as the common `v x y z r g b` extension. Each file is written to a
/// temporary name and renamed.
pub fn write_obj(mesh: &Mesh, path: &Path) -> Result<()> {
    use std::fmt::Write as _;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "mesh".into());
    let with_mtl = mesh.texture.is_some();
    let mut s = String::with_capacity(mesh.positions.len() * 40 + mesh.triangles.len() * 30);
    s.push_str("# written by diffsvg\n");
    if with_mtl {
        let _ = writeln!(s, "mtllib {stem}.mtl\nusemtl material0");
    }
    for (i, p) in mesh.positions.iter().enumerate() {
        match &mesh.colors {
            Some(c) => {
                let c = c[i];
                let _ = writeln!(s, "v {} {} {} {} {} {}", p[0], p[1], p[2], c[0], c[1], c[2]);
            }
            None => {
                let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
            }
        }
    }
    if let Some(uv) = &mesh.uvs {
        for t in uv {
            let _ = writeln!(s, "vt {} {}", t[0], t[1]);
        }
    }
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        if mesh.uvs.is_some() {
            let _ = writeln!(s, "f {a}/{a} {b}/{b} {c}/{c}");
        } else {
            let _ = writeln!(s, "f {a} {b} {c}");
        }
    }
    if let Some(tex) = &mesh.texture {
        let dir = path.parent().unwrap_or(Path::new(""));
        tex.to_image().save_png(dir.join(format!("{stem}.png")))?;
        let mtl = format!("newmtl material0\nKd 1 1 1\nmap_Kd {stem}.png\n");
        write_atomic(&dir.join(format!("{stem}.mtl")), mtl.as_bytes())?;
    }
    write_atomic(path, s.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("diffsvg-mesh-io-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn obj_round_trip_keeps_positions_uvs_colors_and_texture() {
        let d = tmp("rt");
        let mut m = super::super::icosphere(1, 0.7);
        m.colors = Some(
            m.positions
                .iter()
                .map(|p| [p[0].abs(), p[1].abs(), 0.5])
                .collect(),
        );
        m.uvs = Some(
            m.positions
                .iter()
                .map(|p| [0.5 + 0.5 * p[0], 0.5 + 0.5 * p[1]])
                .collect(),
        );
        m.texture = Some(Texture {
            width: 2,
            height: 2,
            data: vec![
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 1.0, 1.0],
            ],
        });
        let p = d.join("ball.obj");
        write_obj(&m, &p).unwrap();
        let back = read_obj(&p).unwrap();
        assert_eq!(back.triangles.len(), m.triangles.len());
        assert_eq!(back.positions.len(), m.positions.len());
        // tobj may reorder vertices; compare each triangle's corners.
        for (ta, tb) in m.triangles.iter().zip(&back.triangles) {
            for k in 0..3 {
                let (a, b) = (m.positions[ta[k] as usize], back.positions[tb[k] as usize]);
                for c in 0..3 {
                    assert!((a[c] - b[c]).abs() < 1e-6, "{a:?} vs {b:?}");
                }
            }
        }
        let t = back.texture.as_ref().expect("texture read back");
        assert_eq!((t.width, t.height), (2, 2));
        assert!((t.data[0][0] - 1.0).abs() < 1e-6 && t.data[1][1] > 0.99);
        assert!(back.uvs.is_some());
        let (c0, c1) = (
            m.colors.as_ref().unwrap(),
            back.colors.as_ref().expect("colors read back"),
        );
        assert!(
            (c0[m.triangles[0][0] as usize][0] - c1[back.triangles[0][0] as usize][0]).abs() < 1e-6
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn bad_obj_files_get_one_error_naming_the_file() {
        let d = tmp("bad");
        let cases: [(&str, &str, &str); 4] = [
            ("empty.obj", "# nothing\n", "no faces"),
            ("range.obj", "v 0 0 0\nv 1 0 0\nf 1 2 9\n", "bad.obj"),
            (
                "nan.obj",
                "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
                "non-finite",
            ),
            (
                "mtl.obj",
                "mtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n",
                "missing.mtl",
            ),
        ];
        for (name, text, want) in cases {
            let p = d.join(name);
            std::fs::write(&p, text).unwrap();
            let e = read_obj(&p).unwrap_err().to_string();
            let want = if want == "bad.obj" { name } else { want };
            assert!(e.contains(want), "{name}: {e}");
            assert!(e.contains(name) || e.contains("missing.mtl"), "{name}: {e}");
        }
        let e = read_obj(&d.join("absent.obj")).unwrap_err().to_string();
        assert!(e.contains("absent.obj"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn spot_loads_when_the_data_is_there() {
        let Some(dir) = std::env::var_os("DIFFSVG_DATA")
            .map(PathBuf::from)
            .or_else(|| Some(Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data")))
            .map(|d| d.join("meshes/spot/spot.obj"))
            .filter(|p| p.exists())
        else {
            eprintln!("skipped: spot.obj not found (set DIFFSVG_DATA)");
            return;
        };
        let m = read_obj(&dir).unwrap();
        assert_eq!(m.triangles.len(), 5856);
        let t = m.texture.as_ref().expect("spot is textured");
        assert_eq!((t.width, t.height), (1024, 1024));
    }
}
