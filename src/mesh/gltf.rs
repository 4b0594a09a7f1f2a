//! glTF 2.0 reading (`.gltf` with its buffers and images beside it or in data URIs, and
//! binary `.glb`), through the `gltf` crate's document model; buffers and images are read
//! here, bounded.
//!
//! What is read: every triangle primitive of every mesh instanced by the default scene's
//! node tree (or by every root node when the file has no scene), placed by its nodes'
//! transforms (a mirroring transform keeps the triangles' front side); `POSITION`,
//! `TEXCOORD_0` (glTF's v runs down; it is flipped to OBJ's v up) and `COLOR_0` times the
//! material's base color factor; the base color texture of the first textured material
//! (one texture per mesh, as for OBJ). glTF's vertex colors and factors are linear; they
//! are written into the mesh as sRGB values, the encoding of the texture they multiply.
//! Triangle strips and fans are unrolled; points and lines are skipped.

use std::path::Path;

use base64::Engine as _;

use super::io::invalid;
use super::{Mesh, Texture};
use crate::Image;
use crate::error::Result;
use crate::image_io::{decode_embedded, read_bounded};
use crate::limits::{MAX_IMAGE_PIXELS, MAX_MESH_FILE_BYTES, MAX_MESH_TRIANGLES, MAX_MESH_VERTICES};

/// Nodes deeper than this in a scene's tree are refused (the format forbids cycles; this
/// bounds a file that has one anyway).
const MAX_NODE_DEPTH: usize = 64;

/// Reads a glTF 2.0 mesh (`.gltf` or `.glb`): what is read is listed in docs/mesh.md. Every buffer
/// and image is read bounded ([`MAX_MESH_FILE_BYTES`] each, images checked from their
/// header), vertex and triangle counts are added up from the accessors' declared counts
/// before any is read ([`MAX_MESH_VERTICES`], [`MAX_MESH_TRIANGLES`]); every error names
/// the file.
pub fn read_gltf(path: &Path) -> Result<Mesh> {
    let bytes = read_bounded(path, MAX_MESH_FILE_BYTES)?;
    let file = ::gltf::Gltf::from_slice(&bytes)
        .map_err(|e| invalid(path, format!("malformed glTF: {e}")))?;
    let doc = &file.document;
    let buffers: Vec<Vec<u8>> = doc
        .buffers()
        .map(|b| {
            let data = match b.source() {
                ::gltf::buffer::Source::Bin => file.blob.clone().ok_or_else(|| {
                    invalid(path, "a buffer refers to a missing GLB binary chunk")
                })?,
                ::gltf::buffer::Source::Uri(uri) => read_uri(path, uri)?,
            };
            if data.len() < b.length() {
                return Err(invalid(
                    path,
                    format!(
                        "buffer {} holds {} bytes, fewer than the {} it declares",
                        b.index(),
                        data.len(),
                        b.length()
                    ),
                ));
            }
            Ok(data)
        })
        .collect::<Result<_>>()?;
    // The mesh instances: (mesh, world transform), counted before anything is read.
    let roots: Vec<::gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => doc.nodes().collect(),
    };
    let mut instances = Vec::new();
    for n in roots {
        collect_instances(path, n, IDENTITY4, 0, &mut instances)?;
    }
    let (mut nv, mut nt) = (0usize, 0usize);
    for (m, _) in &instances {
        for p in m.primitives() {
            let v = p.get(&::gltf::Semantic::Positions).map_or(0, |a| a.count());
            let idx = p.indices().map_or(v, |a| a.count());
            nv = nv.saturating_add(v);
            nt = nt.saturating_add(idx);
        }
    }
    if nv > MAX_MESH_VERTICES {
        return Err(invalid(
            path,
            format!("{nv} vertices exceed the limit of {MAX_MESH_VERTICES}"),
        ));
    }
    if nt / 3 > MAX_MESH_TRIANGLES {
        return Err(invalid(
            path,
            format!(
                "{} triangles exceed the limit of {MAX_MESH_TRIANGLES}",
                nt / 3
            ),
        ));
    }
    for (m, _) in &instances {
        for p in m.primitives() {
            for a in p.attributes().map(|(_, a)| a).chain(p.indices()) {
                check_accessor(path, &a, &buffers)?;
            }
        }
    }
    let mut mesh = Mesh::default();
    let (mut uvs, mut colors) = (Vec::new(), Vec::new());
    let (mut any_uv, mut all_uv, mut any_color) = (false, true, false);
    let mut texture: Option<::gltf::Texture> = None;
    for (m, t) in &instances {
        for p in m.primitives() {
            let mode = p.mode();
            use ::gltf::mesh::Mode;
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                continue;
            }
            let reader = p.reader(|b| buffers.get(b.index()).map(|d| &d[..]));
            let Some(pos) = reader.read_positions() else {
                return Err(invalid(
                    path,
                    format!("mesh {} has a primitive without POSITION", m.index()),
                ));
            };
            let base = mesh.positions.len();
            mesh.positions.extend(pos.map(|q| transform_point(t, q)));
            let n = mesh.positions.len() - base;
            let material = p.material();
            let pbr = material.pbr_metallic_roughness();
            let factor = pbr.base_color_factor().map(|v| v as f64);
            if let Some(info) = pbr.base_color_texture() {
                match &texture {
                    None => texture = Some(info.texture()),
                    Some(t0) if t0.source().index() == info.texture().source().index() => {}
                    Some(_) => {
                        return Err(invalid(
                            path,
                            "its materials use more than one base color texture (a mesh has one)",
                        ));
                    }
                }
            }
            match reader.read_tex_coords(0) {
                Some(tc) => {
                    any_uv = true;
                    let before = uvs.len();
                    uvs.extend(tc.into_f32().map(|[u, v]| [u as f64, 1.0 - v as f64]));
                    if uvs.len() - before != n {
                        return Err(invalid(
                            path,
                            format!("mesh {}: TEXCOORD_0 and POSITION counts differ", m.index()),
                        ));
                    }
                }
                None => {
                    all_uv = false;
                    uvs.extend(std::iter::repeat_n([0.0; 2], n));
                }
            }
            let white = factor[..3].iter().all(|&c| c == 1.0);
            match reader.read_colors(0) {
                Some(c) => {
                    any_color = true;
                    let before = colors.len();
                    colors.extend(
                        c.into_rgb_f32()
                            .map(|c| std::array::from_fn(|i| srgb(c[i] as f64 * factor[i]))),
                    );
                    if colors.len() - before != n {
                        return Err(invalid(
                            path,
                            format!("mesh {}: COLOR_0 and POSITION counts differ", m.index()),
                        ));
                    }
                }
                None => {
                    any_color |= !white;
                    let c: [f64; 3] = std::array::from_fn(|i| srgb(factor[i]));
                    colors.extend(std::iter::repeat_n(c, n));
                }
            }
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..n as u32).collect(),
            };
            if let Some(&bad) = indices.iter().find(|&&i| i as usize >= n) {
                return Err(invalid(
                    path,
                    format!("mesh {}: index {bad} past its {n} vertices", m.index()),
                ));
            }
            let mirrored = det3(t) < 0.0;
            let b = base as u32;
            let mut push = |a: u32, c: u32, d: u32| {
                let tri = if mirrored { [a, d, c] } else { [a, c, d] };
                mesh.triangles.push(tri.map(|i| i + b));
            };
            match mode {
                Mode::Triangles => {
                    for t in indices.chunks_exact(3) {
                        push(t[0], t[1], t[2]);
                    }
                }
                Mode::TriangleStrip => {
                    for (k, w) in indices.windows(3).enumerate() {
                        if k % 2 == 0 {
                            push(w[0], w[1], w[2]);
                        } else {
                            push(w[1], w[0], w[2]);
                        }
                    }
                }
                _ => {
                    for w in indices.get(1..).unwrap_or_default().windows(2) {
                        push(indices[0], w[0], w[1]);
                    }
                }
            }
        }
    }
    if mesh.triangles.is_empty() {
        return Err(invalid(path, "no triangles"));
    }
    if any_uv && all_uv {
        mesh.uvs = Some(uvs);
    }
    if any_color {
        mesh.colors = Some(colors);
    }
    if let Some(t) = texture {
        if mesh.uvs.is_none() {
            return Err(invalid(
                path,
                "a material has a base color texture but not every primitive has TEXCOORD_0",
            ));
        }
        let img = read_image(path, &t.source(), &buffers)?;
        mesh.texture = Some(Texture::from_image(&img));
    }
    mesh.validate(path)?;
    Ok(mesh)
}

/// Refuses an accessor whose declared elements do not all lie in its buffer view, or a
/// view that does not lie in its buffer (the reader would stop short without a word), and
/// sparse accessors (not read).
fn check_accessor(path: &Path, a: &::gltf::Accessor, buffers: &[Vec<u8>]) -> Result<()> {
    let bad = |why: &str| invalid(path, format!("accessor {} {why}", a.index()));
    if a.sparse().is_some() {
        return Err(bad("is sparse, which is not read"));
    }
    let Some(view) = a.view() else {
        return Err(bad("has no buffer view"));
    };
    let data = buffers.get(view.buffer().index()).map_or(0, Vec::len);
    if view.offset().saturating_add(view.length()) > data {
        return Err(bad("has a buffer view past the end of its buffer"));
    }
    let stride = view.stride().unwrap_or(a.size());
    let end = match a.count() {
        0 => 0,
        n => (n - 1)
            .saturating_mul(stride)
            .saturating_add(a.offset())
            .saturating_add(a.size()),
    };
    if end > view.length() {
        return Err(bad(&format!(
            "declares {} elements, past the end of its buffer view",
            a.count()
        )));
    }
    Ok(())
}

/// A column-major 4×4 matrix, glTF's layout.
type Mat4 = [[f64; 4]; 4];

const IDENTITY4: Mat4 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    std::array::from_fn(|c| std::array::from_fn(|r| (0..4).map(|k| a[k][r] * b[c][k]).sum()))
}

fn transform_point(m: &Mat4, p: [f32; 3]) -> [f64; 3] {
    let p = p.map(|v| v as f64);
    std::array::from_fn(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
}

/// The determinant of the upper-left 3×3 block (negative for a mirroring transform).
fn det3(m: &Mat4) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[2][1] * m[1][2])
        - m[1][0] * (m[0][1] * m[2][2] - m[2][1] * m[0][2])
        + m[2][0] * (m[0][1] * m[1][2] - m[1][1] * m[0][2])
}

/// The sRGB encoding of a linear value in `[0, 1]`.
fn srgb(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v == 1.0 {
        1.0
    } else if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The meshes under `node` with their world transforms (`parent` times the node's own).
fn collect_instances<'a>(
    path: &Path,
    node: ::gltf::Node<'a>,
    parent: Mat4,
    depth: usize,
    out: &mut Vec<(::gltf::Mesh<'a>, Mat4)>,
) -> Result<()> {
    if depth > MAX_NODE_DEPTH {
        return Err(invalid(
            path,
            format!("its node tree is deeper than {MAX_NODE_DEPTH} (a cycle?)"),
        ));
    }
    let own = node.transform().matrix().map(|c| c.map(|v| v as f64));
    let world = mul(&parent, &own);
    if !world.iter().flatten().all(|v| v.is_finite()) {
        return Err(invalid(
            path,
            format!("node {} has a non-finite transform", node.index()),
        ));
    }
    if let Some(m) = node.mesh() {
        out.push((m, world));
        // Instancing multiplies meshes: bounded by the same counts, checked as they grow.
        if out.len() > MAX_MESH_TRIANGLES {
            return Err(invalid(path, "too many mesh instances"));
        }
    }
    for c in node.children() {
        collect_instances(path, c, world, depth + 1, out)?;
    }
    Ok(())
}

/// The bytes of a buffer or image URI: a base64 `data:` URI, or a file relative to the
/// glTF's folder.
fn read_uri(path: &Path, uri: &str) -> Result<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((_, data)) = rest.split_once(";base64,") else {
            return Err(invalid(path, "a data URI that is not base64"));
        };
        if data.len() as u64 > MAX_MESH_FILE_BYTES / 3 * 4 {
            return Err(invalid(path, "a data URI past the file size limit"));
        }
        return base64::engine::general_purpose::STANDARD
            .decode(data)
            .map_err(|e| invalid(path, format!("a data URI is not valid base64: {e}")));
    }
    if uri.contains("://") {
        return Err(invalid(
            path,
            format!("refers to {uri:?}, which is not a local file"),
        ));
    }
    let dir = path.parent().unwrap_or(Path::new(""));
    read_bounded(&dir.join(uri.replace("%20", " ")), MAX_MESH_FILE_BYTES)
}

/// A glTF image: from a buffer view or a URI, checked from its header before decoding.
fn read_image(path: &Path, img: &::gltf::Image, buffers: &[Vec<u8>]) -> Result<Image> {
    let bytes = match img.source() {
        ::gltf::image::Source::View { view, .. } => {
            let data = &buffers[view.buffer().index()];
            let (a, n) = (view.offset(), view.length());
            data.get(a..a.saturating_add(n))
                .ok_or_else(|| invalid(path, "an image's buffer view lies past its buffer"))?
                .to_vec()
        }
        ::gltf::image::Source::Uri { uri, .. } => read_uri(path, uri)?,
    };
    let (w, h, rgba) = decode_embedded(&bytes, MAX_IMAGE_PIXELS)
        .map_err(|e| invalid(path, format!("its base color texture {e}")))?;
    Ok(Image::from_rgba8(w, h, &rgba))
}

/// The linear value of an sRGB-encoded one in `[0, 1]` (the inverse of [`srgb`]).
fn linear(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Writes `mesh` as glTF 2.0: binary `.glb`, or `.gltf` with its buffer in a `data:` URI
/// (chosen by the extension). One mesh, one node: `POSITION` (`f32`), `TEXCOORD_0` (v
/// flipped to glTF's v down), `COLOR_0` (converted from the mesh's sRGB values to glTF's
/// linear ones), `u32` indices, and with a texture a material whose base color texture
/// is the texture as PNG (inside the buffer), sampled bilinearly and repeated, as
/// [`render`](super::render::render) samples it. [`read_gltf`] reads the file back to the same
/// mesh (positions and UVs rounded to `f32`, colors within 1e-6). Refused, before
/// anything is written, when the file would pass [`MAX_MESH_FILE_BYTES`] (which the
/// reader refuses); written to a temporary file and renamed.
pub fn write_gltf(mesh: &Mesh, path: &Path) -> Result<()> {
    use serde_json::json;
    let glb = match super::MeshFormat::of(path) {
        Some(super::MeshFormat::Glb) => true,
        Some(super::MeshFormat::Gltf) => false,
        _ => return Err(invalid(path, "a glTF file ends in .gltf or .glb")),
    };
    mesh.validate(path)?;
    let n = mesh.positions.len();
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    // Appends `bytes` as a buffer view (4-byte aligned) and returns its index.
    let mut view = |bin: &mut Vec<u8>, bytes: &[u8], target: Option<u32>| {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let mut v = json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        bin.extend_from_slice(bytes);
        views.push(v);
        views.len() - 1
    };
    let floats = |rows: &mut dyn Iterator<Item = f32>| -> Vec<u8> {
        rows.flat_map(f32::to_le_bytes).collect()
    };
    const ARRAY_BUFFER: u32 = 34962;
    const ELEMENT_ARRAY_BUFFER: u32 = 34963;
    const FLOAT: u32 = 5126;
    let pos: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.map(|v| v as f32)).collect();
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in &pos {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if n == 0 {
        (lo, hi) = ([0.0; 3], [0.0; 3]);
    }
    let v = view(
        &mut bin,
        &floats(&mut pos.iter().flatten().copied()),
        Some(ARRAY_BUFFER),
    );
    accessors.push(json!({"bufferView": v, "componentType": FLOAT, "count": n,
        "type": "VEC3", "min": lo, "max": hi}));
    let mut attributes = json!({"POSITION": accessors.len() - 1});
    if let Some(uv) = &mesh.uvs {
        let mut it = uv.iter().flat_map(|t| [t[0] as f32, (1.0 - t[1]) as f32]);
        let v = view(&mut bin, &floats(&mut it), Some(ARRAY_BUFFER));
        accessors
            .push(json!({"bufferView": v, "componentType": FLOAT, "count": n, "type": "VEC2"}));
        attributes["TEXCOORD_0"] = json!(accessors.len() - 1);
    }
    if let Some(c) = &mesh.colors {
        let mut it = c.iter().flat_map(|c| c.map(|v| linear(v) as f32));
        let v = view(&mut bin, &floats(&mut it), Some(ARRAY_BUFFER));
        accessors
            .push(json!({"bufferView": v, "componentType": FLOAT, "count": n, "type": "VEC3"}));
        attributes["COLOR_0"] = json!(accessors.len() - 1);
    }
    let idx: Vec<u8> = mesh
        .triangles
        .iter()
        .flatten()
        .flat_map(|i| i.to_le_bytes())
        .collect();
    let v = view(&mut bin, &idx, Some(ELEMENT_ARRAY_BUFFER));
    accessors.push(json!({"bufferView": v, "componentType": 5125,
        "count": mesh.triangles.len() * 3, "type": "SCALAR"}));
    let mut primitive =
        json!({"attributes": attributes, "indices": accessors.len() - 1, "mode": 4});
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "diffsvg"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
    });
    if let Some(t) = &mesh.texture {
        let img = t.to_image();
        let png = crate::image_io::encode_png_rgba8(img.width, img.height, &img.to_rgba8());
        let v = view(&mut bin, &png, None);
        primitive["material"] = json!(0);
        doc["materials"] = json!([{"pbrMetallicRoughness": {
            "baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 1.0}}]);
        // Bilinear (LINEAR = 9729) and repeated (REPEAT = 10497), as the renderer samples.
        doc["samplers"] =
            json!([{"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}]);
        doc["textures"] = json!([{"source": 0, "sampler": 0}]);
        doc["images"] = json!([{"bufferView": v, "mimeType": "image/png"}]);
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    doc["meshes"] = json!([{"primitives": [primitive]}]);
    doc["accessors"] = json!(accessors);
    doc["bufferViews"] = json!(views);
    doc["buffers"] = if glb {
        json!([{"byteLength": bin.len()}])
    } else {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&bin)
        );
        json!([{"byteLength": bin.len(), "uri": uri}])
    };
    let mut text = serde_json::to_vec(&doc).expect("a JSON value serializes");
    let bytes = if glb {
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let total = 12 + 8 + text.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total.min(u32::MAX as usize) as u32).to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    } else {
        text
    };
    if bytes.len() as u64 > MAX_MESH_FILE_BYTES {
        return Err(invalid(
            path,
            format!(
                "the glTF would take {} bytes, above the {MAX_MESH_FILE_BYTES} a mesh file may \
                 (diffsvg would refuse to read it); write OBJ instead",
                bytes.len()
            ),
        ));
    }
    crate::image_io::write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A glTF of two triangles (a unit square in z = 0) under a node that moves it by
    /// (1, 2, 3) and mirrors x, with UVs, a red base color factor and the buffer in a
    /// data URI; `glb` wraps the same JSON and buffer as a binary file.
    fn square(glb: bool) -> Vec<u8> {
        let mut buf = Vec::new();
        for p in [
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ] {
            for v in p {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        for t in [[0.0f32, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]] {
            for v in t {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        for i in [0u16, 1, 2, 0, 2, 3] {
            buf.extend_from_slice(&i.to_le_bytes());
        }
        let uri = match glb {
            true => String::new(),
            false => format!(
                r#","uri":"data:application/octet-stream;base64,{}""#,
                base64::engine::general_purpose::STANDARD.encode(&buf)
            ),
        };
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
            "nodes":[{{"mesh":0,"translation":[1,2,3],"scale":[-1,1,1]}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":1}},"indices":2,"material":0}}]}}],
            "materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[1,0,0,1]}}}}],
            "buffers":[{{"byteLength":{len}{uri}}}],
            "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":32}},{{"buffer":0,"byteOffset":80,"byteLength":12}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
                         {{"bufferView":1,"componentType":5126,"count":4,"type":"VEC2"}},
                         {{"bufferView":2,"componentType":5123,"count":6,"type":"SCALAR"}}]}}"#,
            len = buf.len()
        );
        if !glb {
            return json.into_bytes();
        }
        let mut j = json.into_bytes();
        while j.len() % 4 != 0 {
            j.push(b' ');
        }
        while buf.len() % 4 != 0 {
            buf.push(0);
        }
        let total = 12 + 8 + j.len() + 8 + buf.len();
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(j.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&j);
        out.extend_from_slice(&(buf.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&buf);
        out
    }

    fn scratch(name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("diffsvg-gltf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn gltf_and_glb_read_to_the_same_placed_mesh() {
        for (name, glb) in [("square.gltf", false), ("square.glb", true)] {
            let m = read_gltf(&scratch(name, &square(glb))).unwrap();
            // Moved by (1, 2, 3) after mirroring x.
            assert_eq!(m.positions[1], [0.0, 2.0, 3.0], "{name}");
            assert_eq!(m.positions[2], [0.0, 3.0, 3.0], "{name}");
            // The mirror flips the order so that the front stays the front.
            assert_eq!(m.triangles, vec![[0, 2, 1], [0, 3, 2]], "{name}");
            // v flipped to OBJ's v up.
            assert_eq!(m.uvs.as_ref().unwrap()[0], [0.0, 0.0], "{name}");
            assert_eq!(m.uvs.as_ref().unwrap()[2], [1.0, 1.0], "{name}");
            assert_eq!(m.colors.as_ref().unwrap()[3], [1.0, 0.0, 0.0], "{name}");
        }
    }

    #[test]
    fn bad_gltf_files_are_one_line_errors() {
        let good = String::from_utf8(square(false)).unwrap();
        let cases = [
            ("garbage.gltf", "not json".to_string(), "malformed glTF"),
            (
                "index.gltf",
                good.replace(r#""count":6"#, r#""count":600"#),
                "past the end of its buffer view",
            ),
            (
                "huge.gltf",
                good.replace(
                    r#""count":4,"type":"VEC3""#,
                    r#""count":40000000,"type":"VEC3""#,
                ),
                "",
            ),
            (
                "remote.gltf",
                good.replace(
                    "data:application/octet-stream;base64,",
                    "https://example.com/",
                ),
                "not a local file",
            ),
        ];
        for (name, text, needle) in cases {
            let e = read_gltf(&scratch(name, text.as_bytes()))
                .unwrap_err()
                .to_string();
            assert!(e.contains(name), "{e}");
            assert!(e.contains(needle), "{name}: {e}");
            assert!(!e.contains('\n'), "{e}");
        }
        let glb = square(true);
        for cut in [4, 13, 30, glb.len() - 5] {
            let e = read_gltf(&scratch("cut.glb", &glb[..cut])).unwrap_err();
            assert!(e.to_string().contains("cut.glb"), "{e}");
        }
    }

    /// A mesh with everything glTF carries here: UVs, colors and a texture.
    fn textured() -> Mesh {
        let mut m = crate::mesh::icosphere(1, 1.5);
        let n = m.positions.len();
        m.uvs = Some(
            (0..n)
                .map(|i| [i as f64 / n as f64, 1.0 - 0.5 * i as f64 / n as f64])
                .collect(),
        );
        m.colors = Some((0..n).map(|i| [0.1, i as f64 / n as f64, 0.9]).collect());
        let data = (0..12)
            .map(|k| [k as f64 / 11.0, 0.5, 1.0 - k as f64 / 11.0])
            .collect();
        m.texture = Some(Texture {
            width: 4,
            height: 3,
            data,
        });
        m
    }

    #[test]
    fn written_gltf_and_glb_read_back_to_the_same_mesh() {
        let m = textured();
        for name in ["back.glb", "back.gltf"] {
            let path = scratch(name, b"");
            crate::mesh::write_mesh(&m, &path).unwrap();
            let r = read_gltf(&path).unwrap();
            assert_eq!(r.triangles, m.triangles, "{name}");
            let close =
                |a: &[f64], b: &[f64], tol: f64| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol);
            for (a, b) in r.positions.iter().zip(&m.positions) {
                assert!(close(a, b, 1e-6), "{name}: {a:?} {b:?}");
            }
            for (a, b) in r.uvs.as_ref().unwrap().iter().zip(m.uvs.as_ref().unwrap()) {
                assert!(close(a, b, 1e-6), "{name}: {a:?} {b:?}");
            }
            for (a, b) in r
                .colors
                .as_ref()
                .unwrap()
                .iter()
                .zip(m.colors.as_ref().unwrap())
            {
                assert!(close(a, b, 1e-5), "{name}: {a:?} {b:?}");
            }
            let (t, u) = (r.texture.as_ref().unwrap(), m.texture.as_ref().unwrap());
            assert_eq!((t.width, t.height), (u.width, u.height));
            for (a, b) in t.data.iter().zip(&u.data) {
                assert!(close(a, b, 0.5 / 255.0 + 1e-6), "{name}: {a:?} {b:?}");
            }
        }
        // Without colors, UVs or texture: positions and triangles only.
        let plain = crate::mesh::icosphere(0, 1.0);
        let path = scratch("plain.glb", b"");
        write_gltf(&plain, &path).unwrap();
        let r = read_gltf(&path).unwrap();
        assert_eq!(r.triangles, plain.triangles);
        assert!(r.texture.is_none() && r.uvs.is_none());
        // Not a glTF name: refused, nothing written.
        let bad = scratch("x.txt", b"");
        std::fs::remove_file(&bad).unwrap();
        let e = write_gltf(&plain, &bad).unwrap_err().to_string();
        assert!(e.contains("x.txt") && e.contains(".glb"), "{e}");
        assert!(!bad.exists());
    }
}
