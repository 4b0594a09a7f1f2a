//! Reading the sparse point cloud that initializes 3D Gaussians (`points3d.ply` beside
//! NeRF-synthetic data, `sparse_pc.ply` written by nerfstudio from COLMAP).
//!
//! **Accepted files**: PLY 1.0, `ascii` or `binary_little_endian`, whose first element is
//! `vertex` (elements after it, such as `face`, are allowed and never read). Vertex
//! properties may be of any scalar type (`char uchar short ushort int uint float double`
//! and the aliases `int8 … float64`) in any order; `x y z` are required, `red green
//! blue` give colors when all three are present, and every other property is skipped. A
//! `property list` in the vertex element is refused. In an ASCII file each vertex is one
//! line of exactly as many numbers as the vertex has properties.
//!
//! **Units**: positions are world units as written (cast to `f32`); colors are linear
//! RGB in `[0, 1]` for integer colors (`uchar / 255`, `ushort / 65535`) and taken as is
//! when stored as `float` or `double`.
//!
//! **Bounds**: the header must end within [`MAX_PLY_HEADER_BYTES`]; at most
//! [`MAX_GAUSSIANS`] vertices; the file must be long enough for its vertex count before
//! anything is allocated for them (binary: `count × record size`; ASCII: two bytes per
//! value); only the header and the vertex data are read. Coordinates and float colors
//! must be finite. Each failure is one line naming the file and the problem.
//!
//! [`MAX_PLY_HEADER_BYTES`]: crate::limits::MAX_PLY_HEADER_BYTES
//! [`MAX_GAUSSIANS`]: crate::limits::MAX_GAUSSIANS

// Used by the Gaussian trainer's initialization; until it lands, only the tests call in.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use super::ply::{Format, Header, PropertyType, Scalar, header_text, parse_header};
use crate::limits::{MAX_GAUSSIANS, MAX_PLY_HEADER_BYTES};

/// Points and optional colors of a point cloud (a PLY file, COLMAP's `points3D`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Positions, world units.
    pub positions: Vec<[f32; 3]>,
    /// Linear RGB per point in `[0, 1]` (integer colors divided by their type's maximum,
    /// float colors as stored), when the file has `red`, `green` and `blue`.
    pub colors: Option<Vec<[f32; 3]>>,
}

/// File names of a dataset folder's point cloud, in the order they are looked for.
const POINT_CLOUD_NAMES: [&str; 3] = ["points3d.ply", "sparse_pc.ply", "points.ply"];

/// The point cloud file of a dataset folder, if it has one: the first of
/// `points3d.ply`, `sparse_pc.ply` and `points.ply` that is a file.
pub(crate) fn find_point_cloud(dir: &Path) -> Option<PathBuf> {
    POINT_CLOUD_NAMES
        .iter()
        .map(|name| dir.join(name))
        .find(|p| p.is_file())
}

/// Most bytes of one line of an ASCII vertex: far more than any real vertex needs (the
/// header, which declares the properties, is itself at most [`MAX_PLY_HEADER_BYTES`]).
const MAX_ASCII_LINE: u64 = 1 << 20;

/// Where the wanted values sit in a vertex record.
struct Layout {
    /// Number of vertices.
    count: usize,
    /// Type of every property, in file order.
    types: Vec<Scalar>,
    /// Names of every property, in file order, for messages.
    names: Vec<String>,
    /// Columns of `x`, `y`, `z`.
    xyz: [usize; 3],
    /// Columns of `red`, `green`, `blue`, when all three are present.
    rgb: Option<[usize; 3]>,
}

/// Reads the point cloud of a PLY file (module doc). The error is one line naming the
/// file and the problem.
pub(crate) fn load_points(path: &Path) -> Result<PointCloud, String> {
    read_points(path).map_err(|what| format!("{}: {what}", path.display()))
}

fn read_points(path: &Path) -> Result<PointCloud, String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let meta = file.metadata().map_err(|e| e.to_string())?;
    if meta.is_dir() {
        return Err("is a folder, not a file".into());
    }
    let mut reader = BufReader::new(file);
    let mut head = Vec::new();
    (&mut reader)
        .take(MAX_PLY_HEADER_BYTES as u64)
        .read_to_end(&mut head)
        .map_err(|e| e.to_string())?;
    let (text, end) = header_text(&head)?;
    let header = parse_header(text)?;
    let layout = vertex_layout(&header)?;
    // The bytes after the header, when known (a regular file).
    let body_len = meta
        .is_file()
        .then(|| meta.len().saturating_sub(end as u64));
    let body = std::io::Cursor::new(&head[end..]).chain(reader);
    match header.format {
        Format::Ascii => read_ascii(body, &layout, body_len),
        Format::BinaryLittleEndian => read_binary(body, &layout, body_len),
        Format::BinaryBigEndian => {
            Err("PLY format binary_big_endian: only ascii and binary_little_endian are read".into())
        }
    }
}

/// Checks the vertex element of `header` and finds the columns of the wanted values.
fn vertex_layout(header: &Header) -> Result<Layout, String> {
    let vertex = match header.elements.first() {
        Some(e) if e.name == "vertex" => e,
        Some(e) => {
            return Err(format!(
                "PLY element \"{}\" before the vertex element: the vertices must come first",
                e.name
            ));
        }
        None => return Err("PLY header has no vertex element".into()),
    };
    if vertex.count > MAX_GAUSSIANS as u64 {
        return Err(format!(
            "{} vertices, above the limit of {MAX_GAUSSIANS}",
            vertex.count
        ));
    }
    let mut types = Vec::with_capacity(vertex.properties.len());
    for p in &vertex.properties {
        match p.ty {
            PropertyType::Scalar(t) => types.push(t),
            PropertyType::List { .. } => {
                return Err(format!(
                    "vertex property {} is a list ({}); only scalar vertex properties are read",
                    p.name,
                    p.ty.name()
                ));
            }
        }
    }
    let names: Vec<String> = vertex.properties.iter().map(|p| p.name.clone()).collect();
    let find = |name: &str| names.iter().position(|n| n == name);
    let need = |name: &str| find(name).ok_or_else(|| format!("vertex property {name} missing"));
    let xyz = [need("x")?, need("y")?, need("z")?];
    let rgb = match (find("red"), find("green"), find("blue")) {
        (Some(r), Some(g), Some(b)) => Some([r, g, b]),
        _ => None,
    };
    if let Some(cols) = rgb {
        for c in cols {
            if matches!(
                types[c],
                Scalar::I8 | Scalar::I16 | Scalar::I32 | Scalar::U32
            ) {
                return Err(format!(
                    "color property {} is of type {}; colors must be uchar, ushort, float or double",
                    names[c],
                    types[c].name()
                ));
            }
        }
    }
    Ok(Layout {
        count: vertex.count as usize,
        types,
        names,
        xyz,
        rgb,
    })
}

impl Layout {
    /// An empty cloud with room for every vertex.
    fn cloud(&self) -> PointCloud {
        PointCloud {
            positions: Vec::with_capacity(self.count),
            colors: self.rgb.map(|_| Vec::with_capacity(self.count)),
        }
    }

    /// Appends vertex `i` from its values (one per property, in file order).
    fn push(&self, cloud: &mut PointCloud, i: usize, values: &[f64]) -> Result<(), String> {
        let mut pos = [0.0f32; 3];
        for (p, &c) in pos.iter_mut().zip(&self.xyz) {
            *p = values[c] as f32;
            if !p.is_finite() {
                return Err(format!(
                    "vertex {i}: coordinate {} = {:?} is not a finite f32",
                    self.names[c], values[c]
                ));
            }
        }
        cloud.positions.push(pos);
        if let (Some(cols), Some(colors)) = (self.rgb, cloud.colors.as_mut()) {
            let mut rgb = [0.0f32; 3];
            for (v, &c) in rgb.iter_mut().zip(&cols) {
                let scale = match self.types[c] {
                    Scalar::U8 => 255.0,
                    Scalar::U16 => 65535.0,
                    _ => 1.0,
                };
                *v = (values[c] / scale) as f32;
                if !v.is_finite() {
                    return Err(format!(
                        "vertex {i}: color {} = {:?} is not a finite f32",
                        self.names[c], values[c]
                    ));
                }
            }
            colors.push(rgb);
        }
        Ok(())
    }
}

/// The message for data shorter than the header's vertex count needs.
fn truncated(layout: &Layout, need: u64, have: u64, unit: &str) -> String {
    format!(
        "truncated: {} vertices of {} properties need at least {need} {unit} after the header, \
         the file has {have}",
        layout.count,
        layout.types.len()
    )
}

/// Reads the packed little-endian vertex records at the start of `body`.
fn read_binary(
    mut body: impl Read,
    layout: &Layout,
    body_len: Option<u64>,
) -> Result<PointCloud, String> {
    let stride: usize = layout.types.iter().map(|t| t.size()).sum();
    // count ≤ MAX_GAUSSIANS and stride ≤ 8 × header bytes: no overflow.
    let need = layout.count as u64 * stride as u64;
    if let Some(have) = body_len.filter(|&have| have < need) {
        return Err(truncated(layout, need, have, "bytes"));
    }
    let mut cloud = layout.cloud();
    let mut record = vec![0u8; stride];
    let mut values = vec![0.0f64; layout.types.len()];
    for i in 0..layout.count {
        body.read_exact(&mut record).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                format!(
                    "truncated: the data ends within vertex {i} of {}",
                    layout.count
                )
            } else {
                e.to_string()
            }
        })?;
        let mut at = 0;
        for (v, &t) in values.iter_mut().zip(&layout.types) {
            let b = &record[at..at + t.size()];
            *v = decode_le(t, b);
            at += t.size();
        }
        layout.push(&mut cloud, i, &values)?;
    }
    Ok(cloud)
}

/// The value of type `t` stored little-endian in `b` (exactly `t.size()` bytes).
fn decode_le(t: Scalar, b: &[u8]) -> f64 {
    match t {
        Scalar::I8 => b[0] as i8 as f64,
        Scalar::U8 => b[0] as f64,
        Scalar::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
        Scalar::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
        Scalar::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        Scalar::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        Scalar::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        Scalar::F64 => f64::from_le_bytes(b[..8].try_into().expect("8 bytes")),
    }
}

/// Reads the ASCII vertex lines at the start of `body`.
fn read_ascii(
    body: impl Read,
    layout: &Layout,
    body_len: Option<u64>,
) -> Result<PointCloud, String> {
    let props = layout.types.len() as u64;
    // Each value takes a digit and a separator (the last one's may be missing).
    let need = (2 * layout.count as u64 * props).saturating_sub(1);
    if let Some(have) = body_len.filter(|&have| have < need) {
        return Err(truncated(layout, need, have, "bytes"));
    }
    let mut body = BufReader::new(body);
    let mut cloud = layout.cloud();
    let mut values = vec![0.0f64; layout.types.len()];
    let mut line = Vec::new();
    let mut i = 0;
    while i < layout.count {
        line.clear();
        let n = (&mut body)
            .take(MAX_ASCII_LINE)
            .read_until(b'\n', &mut line)
            .map_err(|e| e.to_string())?;
        if n == 0 {
            return Err(format!(
                "truncated: the data ends before vertex {i} of {}",
                layout.count
            ));
        }
        if n as u64 == MAX_ASCII_LINE && line.last() != Some(&b'\n') {
            return Err(format!(
                "vertex {i}: line longer than {MAX_ASCII_LINE} bytes"
            ));
        }
        let text =
            std::str::from_utf8(&line).map_err(|_| format!("vertex {i}: line is not text"))?;
        let mut words = text.split_ascii_whitespace().peekable();
        if words.peek().is_none() {
            continue; // a blank line
        }
        let mut got = 0;
        for word in words {
            let Some(v) = values.get_mut(got) else {
                got += 1;
                continue;
            };
            let t = layout.types[got];
            *v = parse_ascii(t, word).ok_or_else(|| {
                format!(
                    "vertex {i}: {} value \"{word}\" is not a number of type {}",
                    layout.names[got],
                    t.name()
                )
            })?;
            got += 1;
        }
        if got != values.len() {
            return Err(format!(
                "vertex {i}: {got} values on its line, expected {} (one per property)",
                values.len()
            ));
        }
        layout.push(&mut cloud, i, &values)?;
        i += 1;
    }
    Ok(cloud)
}

/// A value of type `t` written in decimal: integers must fit their type; floats may be
/// anything Rust parses (non-finite values are refused later, for coordinates and
/// colors).
fn parse_ascii(t: Scalar, word: &str) -> Option<f64> {
    let int = |lo: i64, hi: i64| {
        word.parse::<i64>()
            .ok()
            .filter(|v| (lo..=hi).contains(v))
            .map(|v| v as f64)
    };
    match t {
        Scalar::I8 => int(i8::MIN.into(), i8::MAX.into()),
        Scalar::U8 => int(0, u8::MAX.into()),
        Scalar::I16 => int(i16::MIN.into(), i16::MAX.into()),
        Scalar::U16 => int(0, u16::MAX.into()),
        Scalar::I32 => int(i32::MIN.into(), i32::MAX.into()),
        Scalar::U32 => int(0, u32::MAX.into()),
        Scalar::F32 | Scalar::F64 => word.parse::<f64>().ok(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder of its own in the temporary folder (tests run in parallel).
    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("diffsvg-points-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    const ASCII: &str = "ply\n\
        format ascii 1.0\n\
        comment written by hand\n\
        element vertex 3\n\
        property float x\n\
        property float nx\n\
        property double y\n\
        property float z\n\
        property uchar red\n\
        property uchar green\n\
        property uchar blue\n\
        property int label\n\
        element face 1\n\
        property list uchar int vertex_indices\n\
        end_header\n\
        1.5 0 -2 3e2 255 0 51 7\n\
        -1 0.5 0.25 0 0 255 102 -3\n\
        \n\
        0 0 1e-3 -7.5 10 20 30 0\n\
        3 0 1 2\n";

    #[test]
    fn reads_ascii_with_extra_properties_and_faces() {
        let dir = temp_dir("ascii");
        let p = write(&dir, "a.ply", ASCII.as_bytes());
        let c = load_points(&p).unwrap();
        assert_eq!(
            c.positions,
            vec![[1.5, -2.0, 300.0], [-1.0, 0.25, 0.0], [0.0, 1e-3, -7.5]]
        );
        let colors = c.colors.unwrap();
        assert_eq!(colors[0], [1.0, 0.0, 0.2]);
        assert_eq!(colors[1], [0.0, 1.0, 0.4]);
        assert_eq!(colors[2], [10.0 / 255.0, 20.0 / 255.0, 30.0 / 255.0]);
        // CRLF line ends read the same.
        let p = write(&dir, "crlf.ply", ASCII.replace('\n', "\r\n").as_bytes());
        assert_eq!(load_points(&p).unwrap().positions[2], [0.0, 1e-3, -7.5]);
        // Without blue, no colors.
        let p = write(
            &dir,
            "nob.ply",
            ASCII
                .replace("property uchar blue", "property uchar alpha")
                .as_bytes(),
        );
        assert_eq!(load_points(&p).unwrap().colors, None);
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A binary little-endian file: mixed types, float colors, an extra short, and a face
    /// element with data after the vertices.
    fn binary(points: &[([f64; 3], [f32; 3])], count: usize) -> Vec<u8> {
        let mut b = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {count}\n\
             property double x\nproperty float32 y\nproperty int16 extra\nproperty float z\n\
             property float red\nproperty float green\nproperty float blue\n\
             element face 1\nproperty list uint8 int32 vertex_indices\nend_header\n"
        )
        .into_bytes();
        for (i, (p, c)) in points.iter().enumerate() {
            b.extend_from_slice(&p[0].to_le_bytes());
            b.extend_from_slice(&(p[1] as f32).to_le_bytes());
            b.extend_from_slice(&(-(i as i16) - 1).to_le_bytes());
            b.extend_from_slice(&(p[2] as f32).to_le_bytes());
            for v in c {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        b.push(3);
        for j in 0..3i32 {
            b.extend_from_slice(&j.to_le_bytes());
        }
        b
    }

    const PTS: [([f64; 3], [f32; 3]); 2] = [
        ([1.0, 2.0, 3.0], [0.1, 0.2, 0.3]),
        ([-4.5, 0.0, 1e6], [1.0, 0.0, 0.5]),
    ];

    #[test]
    fn reads_binary_little_endian() {
        let dir = temp_dir("binary");
        let p = write(&dir, "b.ply", &binary(&PTS, 2));
        let c = load_points(&p).unwrap();
        assert_eq!(c.positions, vec![[1.0, 2.0, 3.0], [-4.5, 0.0, 1e6]]);
        assert_eq!(c.colors, Some(vec![[0.1, 0.2, 0.3], [1.0, 0.0, 0.5]]));
        // All scalar types and aliases decode.
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n\
            property char a\nproperty uint8 b\nproperty short c\nproperty ushort d\n\
            property int x\nproperty uint y\nproperty float64 z\nend_header\n"
            .to_vec();
        b.push(0x80);
        b.push(200);
        b.extend_from_slice(&(-300i16).to_le_bytes());
        b.extend_from_slice(&60000u16.to_le_bytes());
        b.extend_from_slice(&(-70000i32).to_le_bytes());
        b.extend_from_slice(&4_000_000_000u32.to_le_bytes());
        b.extend_from_slice(&0.125f64.to_le_bytes());
        let p = write(&dir, "types.ply", &b);
        let c = load_points(&p).unwrap();
        assert_eq!(c.positions, vec![[-70000.0, 4e9, 0.125]]);
        assert_eq!(c.colors, None);
        assert_eq!(decode_le(Scalar::I8, &[0x80]), -128.0);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn refuses_bad_files_naming_them() {
        let dir = temp_dir("bad");
        let err = |name: &str, bytes: &[u8]| {
            let p = write(&dir, name, bytes);
            let e = load_points(&p).unwrap_err();
            assert!(e.starts_with(&format!("{}: ", p.display())), "{e}");
            assert!(!e.contains('\n'), "one line: {e}");
            e
        };
        // Truncated binary: a byte short of the vertices (faces dropped too).
        let full = binary(&PTS, 2);
        let vertex_end = full.len() - 13;
        let e = err("short.ply", &full[..vertex_end - 1]);
        assert!(e.contains("truncated"), "{e}");
        // Exactly the vertices and no faces is fine: they are never read.
        let p = write(&dir, "nofaces.ply", &full[..vertex_end]);
        assert_eq!(load_points(&p).unwrap().positions.len(), 2);
        // Truncated ASCII: the file claims one more vertex than it has.
        let e = err(
            "short-ascii.ply",
            ASCII
                .replace("element vertex 3", "element vertex 4")
                .replace("3 0 1 2\n", "")
                .as_bytes(),
        );
        assert!(e.contains("truncated") || e.contains("vertex 3"), "{e}");
        let e = err(
            "few-values.ply",
            ASCII
                .replace("-1 0.5 0.25 0 0 255 102 -3", "-1 0.5 0.25")
                .as_bytes(),
        );
        assert!(e.contains("vertex 1: 3 values"), "{e}");
        let e = err(
            "no-y.ply",
            ASCII.replace("property double y\n", "").as_bytes(),
        );
        assert!(e.contains("vertex property y missing"), "{e}");
        // NaN and infinity, ASCII and binary.
        let e = err("nan.ply", ASCII.replace("0 0 1e-3", "0 0 nan").as_bytes());
        assert!(e.contains("vertex 2: coordinate y = NaN"), "{e}");
        let mut pts = PTS;
        pts[1].0[0] = f64::INFINITY;
        let e = err("inf.ply", &binary(&pts, 2));
        assert!(e.contains("vertex 1: coordinate x = inf"), "{e}");
        let mut pts = PTS;
        pts[0].0[0] = 1e300; // finite double, infinite as f32
        let e = err("big.ply", &binary(&pts, 2));
        assert!(e.contains("vertex 0: coordinate x = 1e300"), "{e}");
        let e = err(
            "uchar.ply",
            ASCII.replace(" 255 0 51 ", " 256 0 51 ").as_bytes(),
        );
        assert!(e.contains("vertex 0: red value \"256\""), "{e}");
        // A count above the limit is refused from the header alone.
        let e = err(
            "huge.ply",
            format!(
                "ply\nformat binary_little_endian 1.0\nelement vertex {}\n\
                 property float x\nproperty float y\nproperty float z\nend_header\n",
                MAX_GAUSSIANS + 1
            )
            .as_bytes(),
        );
        assert!(e.contains("above the limit"), "{e}");
        // A count within the limit but far beyond the file's length: refused before
        // anything is allocated for it.
        let e = err(
            "long.ply",
            format!(
                "ply\nformat ascii 1.0\nelement vertex {MAX_GAUSSIANS}\n\
                 property float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n"
            )
            .as_bytes(),
        );
        assert!(
            e.contains("truncated") && e.contains("need at least"),
            "{e}"
        );
        let e = err(
            "list.ply",
            ASCII
                .replace("property int label", "property list uchar int label")
                .as_bytes(),
        );
        assert!(e.contains("label is a list"), "{e}");
        let e = err(
            "faces-first.ply",
            b"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int v\n\
              element vertex 0\nproperty float x\nend_header\n",
        );
        assert!(e.contains("element \"face\" before the vertex"), "{e}");
        let e = err(
            "be.ply",
            ASCII
                .replace("format ascii", "format binary_big_endian")
                .as_bytes(),
        );
        assert!(e.contains("binary_big_endian"), "{e}");
        let e = err(
            "weird.ply",
            ASCII
                .replace("property float nx", "property half nx")
                .as_bytes(),
        );
        assert!(e.contains("unknown type half"), "{e}");
        let e = err(
            "int-color.ply",
            ASCII
                .replace("property uchar red", "property int red")
                .as_bytes(),
        );
        assert!(e.contains("color property red is of type int"), "{e}");
        assert!(err("text.ply", b"hello").contains("not a PLY"));
        let e = err("noend.ply", b"ply\nformat ascii 1.0\nelement vertex 0\n");
        assert!(e.contains("end_header"), "{e}");
        let e = load_points(&dir.join("absent.ply")).unwrap_err();
        assert!(e.contains("absent.ply"), "{e}");
        let e = load_points(&dir).unwrap_err();
        assert!(e.contains("folder"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn finds_the_point_cloud_of_a_folder() {
        let dir = temp_dir("find");
        assert_eq!(find_point_cloud(&dir), None);
        write(&dir, "points.ply", b"");
        assert_eq!(find_point_cloud(&dir), Some(dir.join("points.ply")));
        write(&dir, "sparse_pc.ply", b"");
        assert_eq!(find_point_cloud(&dir), Some(dir.join("sparse_pc.ply")));
        std::fs::create_dir_all(dir.join("points3d.ply")).unwrap(); // a folder: not it
        assert_eq!(find_point_cloud(&dir), Some(dir.join("sparse_pc.ply")));
        std::fs::remove_dir_all(&dir).ok();
    }
}
