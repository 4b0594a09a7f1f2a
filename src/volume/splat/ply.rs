//! Saving and loading [`Gaussians`] as PLY files.
//!
//! **Layout** (that of the reference 3D Gaussian splatting code, which common viewers
//! read): an ASCII header, then one little-endian record per Gaussian.
//!
//! ```text
//! ply
//! format binary_little_endian 1.0
//! element vertex N
//! property float x            ┐ mean, world units
//! property float y            │
//! property float z            ┘
//! property float nx           ┐ normals, written as 0, ignored on reading
//! property float ny           │
//! property float nz           ┘
//! property float f_dc_0       ┐ SH constant term of red, green, blue
//! property float f_dc_1       │
//! property float f_dc_2       ┘
//! property float f_rest_0     ┐ 3·((d + 1)² − 1) higher SH terms grouped by channel:
//! …                           │ all of red (coefficients 1 …), then green, then blue
//! property float f_rest_{R−1} ┘ (R = 0, 9, 24 or 45 gives the SH degree d = 0 … 3)
//! property float opacity      logit opacity (before the sigmoid)
//! property float scale_0      ┐ log scales (before exp)
//! property float scale_1      │
//! property float scale_2      ┘
//! property float rot_0        ┐ quaternion w, x, y, z
//! …                           │
//! property float rot_3        ┘
//! end_header
//! ```
//!
//! An [antialiased](Gaussians::antialiased) model has the line `comment diffsvg
//! antialiased` after the format line (other readers skip comments; a model read without
//! it is not antialiased).
//!
//! The file is exactly the header plus `N × 4 × (properties)` bytes.
//!
//! **Reading** is strict: the file must fit [`MAX_SPLAT_BYTES`] (checked before reading)
//! and its header [`MAX_PLY_HEADER_BYTES`]; the format must be `binary_little_endian 1.0`;
//! there must be one element, `vertex`, with at most [`MAX_GAUSSIANS`] entries; every
//! property must be a `float` (`float32`), named once; all of the properties above but
//! the normals must be present, with `f_rest_0 …` numbered without gaps. Other float
//! properties (normals, extras some trainers add) are skipped. The data must be exactly
//! `N` records long, and every value read must be finite and every quaternion non-zero.
//! Each failure is one error naming the file and the problem.
//!
//! [`MAX_SPLAT_BYTES`]: crate::limits::MAX_SPLAT_BYTES
//! [`MAX_PLY_HEADER_BYTES`]: crate::limits::MAX_PLY_HEADER_BYTES
//! [`MAX_GAUSSIANS`]: crate::limits::MAX_GAUSSIANS

use std::path::Path;

use super::Gaussians;
use crate::error::{Error, Result};
use crate::image_io::{read_bounded, write_atomic};
use crate::limits::{MAX_GAUSSIANS, MAX_PLY_HEADER_BYTES, MAX_SPLAT_BYTES};
use crate::volume::sh;

const END_HEADER: &[u8] = b"end_header";

/// The header line that marks an [antialiased](Gaussians::antialiased) model.
const ANTIALIASED: &str = "comment diffsvg antialiased";

/// The header written for `n` Gaussians of SH degree `degree`.
fn header(n: usize, degree: u32, antialiased: bool) -> String {
    let rest = 3 * (sh::coeff_count(degree) - 1);
    let mut h = String::from("ply\nformat binary_little_endian 1.0\n");
    if antialiased {
        h.push_str(ANTIALIASED);
        h.push('\n');
    }
    h.push_str(&format!("element vertex {n}\n"));
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .map(String::from)
    .to_vec();
    names.extend((0..rest).map(|j| format!("f_rest_{j}")));
    names.push("opacity".into());
    names.extend((0..3).map(|j| format!("scale_{j}")));
    names.extend((0..4).map(|j| format!("rot_{j}")));
    for name in names {
        h.push_str("property float ");
        h.push_str(&name);
        h.push('\n');
    }
    h.push_str("end_header\n");
    h
}

/// The file image of `g` (see the module doc); `g` must be valid.
pub(crate) fn to_bytes(g: &Gaussians) -> Vec<u8> {
    let k = g.coeffs_per_channel();
    let n = g.len();
    let h = header(n, g.sh_degree, g.antialiased);
    let floats = 3 + 3 + 3 * k + 1 + 3 + 4;
    let mut b = Vec::with_capacity(h.len() + 4 * floats * n);
    b.extend_from_slice(h.as_bytes());
    let mut put = |v: f32| b.extend_from_slice(&v.to_le_bytes());
    for i in 0..n {
        g.means[i].into_iter().for_each(&mut put);
        [0.0; 3].into_iter().for_each(&mut put);
        let coeffs = &g.sh[3 * k * i..3 * k * (i + 1)];
        (0..3).for_each(|c| put(coeffs[c * k]));
        for c in 0..3 {
            coeffs[c * k + 1..(c + 1) * k].iter().for_each(|&v| put(v));
        }
        put(g.logit_opacities[i]);
        g.log_scales[i].into_iter().for_each(&mut put);
        g.rotations[i].into_iter().for_each(&mut put);
    }
    b
}

/// Writes `g` to `path` as a binary PLY file (module doc), atomically: a temporary file
/// renamed into place, parent folders created, so a failure never leaves a partial file.
/// An invalid model ([`Gaussians::validate`]) is refused, so every file written loads.
pub fn save(g: &Gaussians, path: impl AsRef<Path>) -> Result<()> {
    let path = path.as_ref();
    g.validate().map_err(|what| Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    })?;
    write_atomic(path, &to_bytes(g))
}

/// Reads a Gaussian-splatting PLY file (module doc): one written by [`save`] or by the
/// reference code and the tools that follow its layout.
pub fn load(path: impl AsRef<Path>) -> Result<Gaussians> {
    let path = path.as_ref();
    let bytes = read_bounded(path, MAX_SPLAT_BYTES)?;
    from_bytes(&bytes, path)
}

/// Column of each required property in a record, in the order of the module doc.
struct Columns {
    mean: [usize; 3],
    dc: [usize; 3],
    rest: Vec<usize>,
    opacity: usize,
    scale: [usize; 3],
    rot: [usize; 4],
}

/// Parses a file image; `path` only names the input in errors.
pub(crate) fn from_bytes(b: &[u8], path: &Path) -> Result<Gaussians> {
    let bad = |what: String| Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    };
    let (text, end) = header_text(b).map_err(bad)?;
    let (n, props) = gaussian_header(text).map_err(bad)?;
    let cols = columns(&props).map_err(bad)?;
    let stride = 4 * props.len();
    let data = &b[end..];
    let want = n * stride as u64; // n ≤ MAX_GAUSSIANS, stride < header size: no overflow
    if data.len() as u64 != want {
        return Err(bad(format!(
            "{} data bytes after the header, expected {want} for {n} vertices of {} float properties ({})",
            data.len(),
            props.len(),
            if (data.len() as u64) < want {
                "truncated"
            } else {
                "trailing bytes"
            }
        )));
    }
    let n = n as usize;
    let degree = match cols.rest.len() {
        0 => 0,
        9 => 1,
        24 => 2,
        _ => 3,
    };
    let k = sh::coeff_count(degree);
    let mut g = Gaussians::new(degree);
    g.antialiased = text.lines().any(|l| l.trim_end() == ANTIALIASED);
    g.means.reserve_exact(n);
    g.log_scales.reserve_exact(n);
    g.rotations.reserve_exact(n);
    g.logit_opacities.reserve_exact(n);
    g.sh.reserve_exact(3 * k * n);
    for (i, rec) in data.chunks_exact(stride.max(1)).take(n).enumerate() {
        let get = |col: usize| -> Result<f32> {
            let v = f32::from_le_bytes(rec[4 * col..4 * col + 4].try_into().expect("4 bytes"));
            if v.is_finite() {
                Ok(v)
            } else {
                Err(bad(format!("vertex {i}: property {} is {v}", props[col])))
            }
        };
        let three =
            |c: [usize; 3]| -> Result<[f32; 3]> { Ok([get(c[0])?, get(c[1])?, get(c[2])?]) };
        g.means.push(three(cols.mean)?);
        for c in 0..3 {
            g.sh.push(get(cols.dc[c])?);
            for j in 0..k - 1 {
                g.sh.push(get(cols.rest[c * (k - 1) + j])?);
            }
        }
        g.logit_opacities.push(get(cols.opacity)?);
        g.log_scales.push(three(cols.scale)?);
        let r = cols.rot;
        let rot = [get(r[0])?, get(r[1])?, get(r[2])?, get(r[3])?];
        if rot.iter().all(|&v| v == 0.0) {
            return Err(bad(format!(
                "vertex {i}: rotation quaternion (rot_0 … rot_3) is zero"
            )));
        }
        g.rotations.push(rot);
    }
    Ok(g)
}

/// The text of a PLY file's header and the offset of the data after it: the file must
/// start with a `ply` line, and a line `end_header` (ending in `\n` or `\r\n`) must end
/// within its first [`MAX_PLY_HEADER_BYTES`] bytes. The header must be UTF-8.
pub(crate) fn header_text(b: &[u8]) -> Result<(&str, usize), String> {
    if !b.starts_with(b"ply\n") && !b.starts_with(b"ply\r\n") {
        return Err("not a PLY file (missing \"ply\" on the first line)".into());
    }
    let search = &b[..b.len().min(MAX_PLY_HEADER_BYTES)];
    let end = (1..search.len())
        .filter(|&i| search[i - 1] == b'\n' && search[i..].starts_with(END_HEADER))
        .find_map(|i| {
            let after = &search[i + END_HEADER.len()..];
            if after.starts_with(b"\n") {
                Some(i + END_HEADER.len() + 1)
            } else if after.starts_with(b"\r\n") {
                Some(i + END_HEADER.len() + 2)
            } else {
                None
            }
        })
        .ok_or_else(|| {
            format!(
                "PLY header has no \"end_header\" line within its first {MAX_PLY_HEADER_BYTES} bytes"
            )
        })?;
    let text = std::str::from_utf8(&b[..end]).map_err(|_| "PLY header is not text")?;
    Ok((text, end))
}

/// Encoding of the data after a PLY header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Format {
    /// Whitespace-separated decimal numbers.
    Ascii,
    /// Packed little-endian values.
    BinaryLittleEndian,
    /// Packed big-endian values.
    BinaryBigEndian,
}

impl Format {
    /// The name in the header's `format` line.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Format::Ascii => "ascii",
            Format::BinaryLittleEndian => "binary_little_endian",
            Format::BinaryBigEndian => "binary_big_endian",
        }
    }
}

/// Scalar type of a PLY property (the names of PLY 1.0 and their sized aliases).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    /// `char`, `int8`.
    I8,
    /// `uchar`, `uint8`.
    U8,
    /// `short`, `int16`.
    I16,
    /// `ushort`, `uint16`.
    U16,
    /// `int`, `int32`.
    I32,
    /// `uint`, `uint32`.
    U32,
    /// `float`, `float32`.
    F32,
    /// `double`, `float64`.
    F64,
}

impl Scalar {
    /// The type named `name` in a header, if it is one.
    pub(crate) fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// The PLY 1.0 name (`char`, `uchar`, … `double`).
    pub(crate) fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    /// Size in bytes in a binary file.
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

/// Type of a PLY property.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PropertyType {
    /// One value.
    Scalar(Scalar),
    /// A count of type `count`, then that many values of type `item`.
    List {
        /// Type of the count.
        count: Scalar,
        /// Type of each item.
        item: Scalar,
    },
}

impl PropertyType {
    /// The type as a header writes it with PLY 1.0 names (`float`, `list uchar int`).
    pub(crate) fn name(self) -> String {
        match self {
            PropertyType::Scalar(t) => t.name().to_string(),
            PropertyType::List { count, item } => {
                format!("list {} {}", count.name(), item.name())
            }
        }
    }
}

/// One property of a PLY element, as declared.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Property {
    /// Its name.
    pub name: String,
    /// Its type.
    pub ty: PropertyType,
}

/// One element of a PLY header: its name, count and properties in file order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Element {
    /// Its name (`vertex`, `face`, …).
    pub name: String,
    /// How many entries the data holds.
    pub count: u64,
    /// Properties in the order of the data, names distinct.
    pub properties: Vec<Property>,
}

/// A parsed PLY header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Header {
    /// Encoding of the data.
    pub format: Format,
    /// Elements in the order of the data.
    pub elements: Vec<Element>,
}

/// Parses a PLY header as returned by [`header_text`] (first line `ply`, last line
/// `end_header`): version 1.0 of any format; `comment` and `obj_info` lines skipped;
/// every property of a known scalar type or a list of them, within an element, named
/// once per element. Counts are not limited here: the caller checks them.
pub(crate) fn parse_header(text: &str) -> Result<Header, String> {
    let mut format: Option<Format> = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in text.lines().map(str::trim_end).skip(1) {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", fmt, ver] if format.is_none() => {
                format = Some(match *fmt {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLittleEndian,
                    "binary_big_endian" => Format::BinaryBigEndian,
                    _ => return Err(format!("unknown PLY format {fmt}")),
                });
                if *ver != "1.0" {
                    return Err(format!("PLY version {ver}: only 1.0 is read"));
                }
            }
            ["format", ..] => {
                return Err(format!("malformed or repeated PLY format line \"{line}\""));
            }
            _ if format.is_none() => {
                return Err(format!("PLY header line \"{line}\" before the format line"));
            }
            ["element", name, n] => {
                let count: u64 = n
                    .parse()
                    .map_err(|_| format!("{name} count \"{n}\" is not a number"))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", rest @ ..] if rest.len() >= 2 => {
                let name = rest[rest.len() - 1];
                let types = &rest[..rest.len() - 1];
                let scalar = |t: &str| {
                    Scalar::parse(t).ok_or_else(|| format!("property {name} has unknown type {t}"))
                };
                let ty = match types {
                    [t] => PropertyType::Scalar(scalar(t)?),
                    ["list", count, item] => PropertyType::List {
                        count: scalar(count)?,
                        item: scalar(item)?,
                    },
                    _ => return Err(format!("malformed PLY property line \"{line}\"")),
                };
                let element = elements
                    .last_mut()
                    .ok_or_else(|| format!("PLY property line \"{line}\" before any element"))?;
                if element.properties.iter().any(|p| p.name == name) {
                    return Err(format!("property {name} appears twice"));
                }
                element.properties.push(Property {
                    name: name.to_string(),
                    ty,
                });
            }
            ["end_header"] => break,
            _ => return Err(format!("unexpected PLY header line \"{line}\"")),
        }
    }
    let format = format.ok_or("PLY header has no format line")?;
    Ok(Header { format, elements })
}

/// The vertex count and the property names of a Gaussian-splatting header (module doc):
/// binary little-endian, one element `vertex` of at most [`MAX_GAUSSIANS`] entries,
/// float properties only.
fn gaussian_header(text: &str) -> Result<(u64, Vec<String>), String> {
    let header = parse_header(text)?;
    if header.format != Format::BinaryLittleEndian {
        return Err(format!(
            "PLY format {}: only binary_little_endian is read",
            header.format.name()
        ));
    }
    let vertex = header
        .elements
        .first()
        .ok_or("PLY header has no vertex element")?;
    if let Some((_, e)) =
        (header.elements.iter().enumerate()).find(|(i, e)| *i > 0 || e.name != "vertex")
    {
        return Err(format!(
            "PLY element \"{}\": only one element, vertex, is read",
            e.name
        ));
    }
    let n = vertex.count;
    if n > MAX_GAUSSIANS as u64 {
        return Err(format!(
            "{n} vertices (Gaussians), above the limit of {MAX_GAUSSIANS}"
        ));
    }
    let mut props = Vec::with_capacity(vertex.properties.len());
    for p in &vertex.properties {
        match p.ty {
            PropertyType::Scalar(Scalar::F32) => props.push(p.name.clone()),
            PropertyType::List { .. } => {
                return Err(format!(
                    "property {} is a list; only float properties are read",
                    p.name
                ));
            }
            PropertyType::Scalar(_) => {
                return Err(format!(
                    "property {} is of type {}; only float properties are read",
                    p.name,
                    p.ty.name()
                ));
            }
        }
    }
    Ok((n, props))
}

/// Finds the columns of the required properties and checks the `f_rest` count.
fn columns(props: &[String]) -> Result<Columns, String> {
    let find = |name: &str| {
        props
            .iter()
            .position(|p| p == name)
            .ok_or_else(|| format!("property {name} missing"))
    };
    let rest_count = props.iter().filter(|p| p.starts_with("f_rest_")).count();
    if ![0, 9, 24, 45].contains(&rest_count) {
        return Err(format!(
            "{rest_count} f_rest properties; expected 0, 9, 24 or 45 (SH degree 0 to 3)"
        ));
    }
    if let Some(p) = props.iter().find(|p| {
        p.strip_prefix("f_rest_").is_some_and(|s| {
            s.parse::<usize>()
                .map_or(true, |j| j >= rest_count || j.to_string() != s)
        })
    }) {
        return Err(format!(
            "property {p} out of the f_rest_0 … f_rest_{} range of {rest_count} f_rest properties",
            rest_count.saturating_sub(1)
        ));
    }
    let three = |a: &str, b: &str, c: &str| Ok::<_, String>([find(a)?, find(b)?, find(c)?]);
    Ok(Columns {
        mean: three("x", "y", "z")?,
        dc: three("f_dc_0", "f_dc_1", "f_dc_2")?,
        rest: (0..rest_count)
            .map(|j| find(&format!("f_rest_{j}")))
            .collect::<Result<_, _>>()?,
        opacity: find("opacity")?,
        scale: three("scale_0", "scale_1", "scale_2")?,
        rot: [
            find("rot_0")?,
            find("rot_1")?,
            find("rot_2")?,
            find("rot_3")?,
        ],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(degree: u32, n: usize) -> Gaussians {
        let mut g = Gaussians::new(degree);
        let k3 = 3 * g.coeffs_per_channel();
        for i in 0..n {
            let f = |j: usize| ((i * 31 + j) as f32 * 0.37).sin() * 1.7;
            let sh: Vec<f32> = (0..k3).map(|j| f(100 + j)).collect();
            g.push(
                [f(0), f(1), f(2)],
                [f(3), f(4), f(5)],
                [f(6), f(7), f(8), f(9)],
                f(10),
                &sh,
            );
        }
        g
    }

    /// A file of its own in the temporary folder (tests run in parallel).
    fn temp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("diffsvg-splat-{}-{name}", std::process::id()))
    }

    #[test]
    fn round_trip_is_bit_exact() {
        for (degree, n) in [(0, 5), (3, 7), (1, 0), (2, 3)] {
            let g = sample(degree, n);
            let path = temp(&format!("d{degree}.ply"));
            save(&g, &path).unwrap();
            let h = load(&path).unwrap();
            std::fs::remove_file(&path).ok();
            assert_eq!(h.sh_degree, degree);
            assert_eq!(h.len(), n);
            assert_eq!(to_bytes(&h), to_bytes(&g));
            let bits = |v: &Gaussians| v.sh.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&h), bits(&g));
            assert_eq!(h, g);
        }
    }

    #[test]
    fn the_antialiased_flag_round_trips_in_a_comment() {
        let mut g = sample(1, 4);
        g.antialiased = true;
        let path = temp("aa.ply");
        save(&g, &path).unwrap();
        let text = std::fs::read(&path).unwrap();
        let h = load(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert!(h.antialiased);
        assert_eq!(h, g);
        let head = String::from_utf8_lossy(&text[..200]).into_owned();
        assert!(head.contains("\ncomment diffsvg antialiased\n"), "{head}");
        // Without the line, the same records read as a plain model.
        g.antialiased = false;
        let plain = from_bytes(&to_bytes(&g), Path::new("x.ply")).unwrap();
        assert!(!plain.antialiased);
    }

    /// A header of float properties in the given order.
    fn hand_header(n: usize, names: &[&str]) -> Vec<u8> {
        let mut h =
            format!("ply\nformat binary_little_endian 1.0\ncomment by hand\nelement vertex {n}\n");
        for p in names {
            h += &format!("property float {p}\n");
        }
        h += "end_header\n";
        h.into_bytes()
    }

    fn push_floats(b: &mut Vec<u8>, v: &[f32]) {
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }

    const BASE: [&str; 17] = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0",
        "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ];

    fn hand_degree0() -> Vec<u8> {
        let mut b = hand_header(2, &BASE);
        push_floats(
            &mut b,
            &[
                1., 2., 3., 0., 0., 0., 0.1, 0.2, 0.3, -1., -2., -3., -4., 1., 0., 0., 0.,
            ],
        );
        push_floats(
            &mut b,
            &[
                -1., -2., -3., 0., 0., 0., 0.4, 0.5, 0.6, 2., 0.5, 0.25, 0., 0., 0., 0., 1.,
            ],
        );
        b
    }

    #[test]
    fn reads_a_hand_built_file() {
        let g = from_bytes(&hand_degree0(), Path::new("hand.ply")).unwrap();
        assert_eq!(g.sh_degree, 0);
        assert_eq!(g.means, vec![[1., 2., 3.], [-1., -2., -3.]]);
        assert_eq!(g.sh, vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        assert_eq!(g.logit_opacities, vec![-1., 2.]);
        assert_eq!(g.log_scales, vec![[-2., -3., -4.], [0.5, 0.25, 0.]]);
        assert_eq!(g.rotations, vec![[1., 0., 0., 0.], [0., 0., 0., 1.]]);
        // And our writer puts out the same bytes apart from the comment.
        let ours = to_bytes(&g);
        let hand = hand_degree0();
        let skip = "comment by hand\n".len();
        let at = hand.windows(7).position(|w| w == b"comment").unwrap();
        assert_eq!(ours[..at], hand[..at]);
        assert_eq!(ours[at..], hand[at + skip..]);
    }

    #[test]
    fn f_rest_is_grouped_by_channel() {
        // Degree 1, in a shuffled property order with an extra float property.
        let mut names: Vec<String> = vec!["extra".into()];
        names.extend(BASE.iter().rev().map(|s| s.to_string()));
        names.extend((0..9).map(|j| format!("f_rest_{j}")));
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        let mut b = hand_header(1, &refs);
        let mut rec = vec![7.0f32];
        // BASE reversed: rot_3 … x.
        rec.extend(
            [
                0., 0., 0., 0., 0., 0., 10., 20., 30., 0., 0., 0., 0., 1., 0., 0., 0.,
            ]
            .iter()
            .rev(),
        );
        rec.extend((0..9).map(|j| 100.0 + j as f32));
        push_floats(&mut b, &rec);
        let g = from_bytes(&b, Path::new("deg1.ply")).unwrap();
        assert_eq!(g.sh_degree, 1);
        assert_eq!(g.rotations, vec![[1., 0., 0., 0.]]);
        // Channel-major: R = dc0, rest 0..3; G = dc1, rest 3..6; B = dc2, rest 6..9.
        assert_eq!(
            g.sh,
            vec![
                10., 100., 101., 102., 20., 103., 104., 105., 30., 106., 107., 108.
            ]
        );
        // Written back in the standard order, the grouping is kept.
        let h = from_bytes(&to_bytes(&g), Path::new("again.ply")).unwrap();
        assert_eq!(h, g);
    }

    #[test]
    fn rejects_bad_files_with_reasons() {
        let p = Path::new("bad.ply");
        let good = hand_degree0();
        let err = |b: &[u8]| {
            let e = from_bytes(b, p).unwrap_err().to_string();
            assert!(e.starts_with("bad.ply: "), "names the file: {e}");
            e
        };
        let text = |s: &str| s.as_bytes().to_vec();
        // The good file with one header string replaced (the body is binary).
        let swap = |from: &str, to: &str| {
            let at = good
                .windows(from.len())
                .position(|w| w == from.as_bytes())
                .unwrap();
            let mut v = good[..at].to_vec();
            v.extend_from_slice(to.as_bytes());
            v.extend_from_slice(&good[at + from.len()..]);
            v
        };
        assert!(err(b"PNG").contains("not a PLY"));
        assert!(err(&good[..good.len() - 1]).contains("truncated"));
        let mut v = good.clone();
        v.push(0);
        assert!(err(&v).contains("trailing"));
        assert!(err(&swap("format binary_little_endian", "format ascii")).contains("ascii"));
        assert!(
            err(&swap(
                "format binary_little_endian",
                "format binary_big_endian"
            ))
            .contains("binary_big_endian")
        );
        assert!(err(&swap("format binary_little_endian", "format foo")).contains("foo"));
        assert!(err(&swap("property float opacity\n", "")).contains("property opacity missing"));
        assert!(
            err(&swap("property float scale_1", "property uchar scale_1"))
                .contains("property scale_1 is of type uchar")
        );
        assert!(err(&swap("property float nz", "property float f_rest_0")).contains("1 f_rest"));
        assert!(
            err(&swap("property float y", "property float x")).contains("property x appears twice")
        );
        // NaN in vertex 1's f_dc_1 (record 1, column 7).
        let mut v = good.clone();
        let at = good.len() - 2 * 17 * 4 + 17 * 4 + 7 * 4;
        v[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = err(&v);
        assert!(e.contains("vertex 1: property f_dc_1 is NaN"), "{e}");
        let mut v = good.clone();
        let at = good.len() - 4 * 4;
        v[at..].copy_from_slice(&[0; 16]);
        assert!(err(&v).contains("vertex 1: rotation quaternion"));
        // A huge count over a tiny body: refused by length, nothing allocated for it.
        let e = err(&swap("element vertex 2", "element vertex 9999999"));
        assert!(e.contains("truncated") && e.contains("9999999"), "{e}");
        let e = err(&swap(
            "element vertex 2",
            "element vertex 18446744073709551615",
        ));
        assert!(e.contains("limit"), "{e}");
        assert!(err(&text("ply\nformat binary_little_endian 1.0\n")).contains("end_header"));
        assert!(
            err(&text(
                "ply\nformat binary_little_endian 1.0\nelement face 0\nend_header\n"
            ))
            .contains("element \"face\"")
        );
        // Loading names the path too.
        let missing = load("/nonexistent/dir/g.ply").unwrap_err().to_string();
        assert!(missing.starts_with("/nonexistent/dir/g.ply"), "{missing}");
    }

    #[test]
    fn refuses_a_file_over_the_size_limit_before_reading() {
        let path = temp("huge.ply");
        // Sparse on most file systems: nothing is written or read.
        let f = std::fs::File::create(&path).unwrap();
        f.set_len(MAX_SPLAT_BYTES + 1).unwrap();
        drop(f);
        let e = load(&path).unwrap_err().to_string();
        std::fs::remove_file(&path).ok();
        assert!(e.contains("huge.ply") && e.contains("limit"), "{e}");
    }

    #[test]
    fn save_refuses_an_invalid_model() {
        let mut g = sample(0, 2);
        g.means[1][2] = f32::INFINITY;
        let e = save(&g, temp("never.ply")).unwrap_err().to_string();
        assert!(
            e.contains("never.ply") && e.contains("Gaussian 1: mean is inf"),
            "{e}"
        );
        assert!(!temp("never.ply").exists());
    }
}
