//! Writes `svg-samples/glyphs/`: the digits 0–9 of DejaVu Sans as SVG outlines.
//!
//! ```sh
//! cargo run --release --example make_glyphs [FONT.ttf] [OUT_DIR]
//! ```
//!
//! Reads `/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf` (Debian's `fonts-dejavu-core`)
//! unless another font is named, and writes into `svg-samples/glyphs/` unless another
//! folder is named:
//!
//! * `0.svg` … `9.svg`: 128×128 SVGs, a white background rectangle and the digit as one
//!   black `<path>` with the font's own commands (`M`, `L`, `Q`, `C`, `Z`; TrueType
//!   quadratics stay `Q`), in font units with y flipped to point down. All ten share one
//!   scale (a square viewBox 1.2 times the largest digit extent), each digit centered.
//! * `segments.csv`: per digit the contours and the font's segment count (lines,
//!   quadratics and cubics, the closing line of a contour included when it has length).
//! * `LICENSE.txt`: the font's license (Bitstream Vera; DejaVu changes are public
//!   domain).

use std::fmt::Write as _;
use std::path::PathBuf;

/// One drawing command in font units, y up.
#[derive(Clone, Copy, Debug)]
enum Cmd {
    Move(f32, f32),
    Line(f32, f32),
    Quad(f32, f32, f32, f32),
    Cubic(f32, f32, f32, f32, f32, f32),
    Close,
}

/// Collects ttf-parser's outline callbacks.
#[derive(Default)]
struct Outline {
    cmds: Vec<Cmd>,
}

impl ttf_parser::OutlineBuilder for Outline {
    fn move_to(&mut self, x: f32, y: f32) {
        self.cmds.push(Cmd::Move(x, y));
    }
    fn line_to(&mut self, x: f32, y: f32) {
        self.cmds.push(Cmd::Line(x, y));
    }
    fn quad_to(&mut self, x1: f32, y1: f32, x: f32, y: f32) {
        self.cmds.push(Cmd::Quad(x1, y1, x, y));
    }
    fn curve_to(&mut self, x1: f32, y1: f32, x2: f32, y2: f32, x: f32, y: f32) {
        self.cmds.push(Cmd::Cubic(x1, y1, x2, y2, x, y));
    }
    fn close(&mut self) {
        self.cmds.push(Cmd::Close);
    }
}

/// A number with at most two decimals and no trailing zeros.
fn num(v: f32) -> String {
    let mut s = format!("{:.2}", v);
    while s.contains('.') && (s.ends_with('0') || s.ends_with('.')) {
        s.pop();
    }
    if s == "-0" { "0".into() } else { s }
}

/// The SVG path data (y flipped) and the counts (contours, segments) of an outline.
/// Zero-length lines are dropped; a contour's last line back to its start is left to `Z`
/// (it still counts as a segment).
fn path_data(cmds: &[Cmd]) -> (String, usize, usize) {
    let p = |x: f32, y: f32| format!("{} {}", num(x), num(-y));
    let mut d = String::new();
    let (mut contours, mut segments) = (0, 0);
    let mut start = (0.0f32, 0.0f32);
    let mut cur = start;
    for (i, c) in cmds.iter().enumerate() {
        let closes_next = matches!(cmds.get(i + 1), Some(Cmd::Close));
        match *c {
            Cmd::Move(x, y) => {
                contours += 1;
                start = (x, y);
                cur = start;
                let _ = write!(d, "M{}", p(x, y));
            }
            Cmd::Line(x, y) => {
                if (x, y) == cur {
                    continue;
                }
                segments += 1;
                cur = (x, y);
                if !(closes_next && (x, y) == start) {
                    let _ = write!(d, "L{}", p(x, y));
                }
            }
            Cmd::Quad(x1, y1, x, y) => {
                segments += 1;
                cur = (x, y);
                let _ = write!(d, "Q{} {}", p(x1, y1), p(x, y));
            }
            Cmd::Cubic(x1, y1, x2, y2, x, y) => {
                segments += 1;
                cur = (x, y);
                let _ = write!(d, "C{} {} {}", p(x1, y1), p(x2, y2), p(x, y));
            }
            Cmd::Close => {
                if cur != start {
                    // ttf-parser always ends a contour on its start point; a font that
                    // does not gets its closing line counted here.
                    segments += 1;
                }
                cur = start;
                d.push('Z');
            }
        }
    }
    (d, contours, segments)
}

/// The license text of the DejaVu fonts, from Debian's copyright file when present.
fn license() -> String {
    let mut out = String::from(
        "The glyph outlines in this folder (0.svg … 9.svg) are the digits of DejaVu Sans\n\
         (https://dejavu-fonts.github.io/), copied unchanged from DejaVuSans.ttf and written\n\
         as SVG paths by examples/make_glyphs.rs.\n\n\
         Fonts are (c) Bitstream (see below). DejaVu changes are in public domain.\n\n\
         Copyright (c) 2003 by Bitstream, Inc. All Rights Reserved. Bitstream Vera is\n\
         a trademark of Bitstream, Inc.\n\n",
    );
    let debian =
        std::fs::read_to_string("/usr/share/doc/fonts-dejavu-core/copyright").unwrap_or_default();
    // The `License: bitstream-vera` paragraph: indented lines, " ." for blank lines.
    let mut text = String::new();
    let mut inside = false;
    for line in debian.lines() {
        if line.starts_with("License: bitstream-vera") {
            inside = true;
            continue;
        }
        if inside {
            match line.strip_prefix(' ') {
                Some(".") => text.push('\n'),
                Some(l) => {
                    text.push_str(l);
                    text.push('\n');
                }
                None => break,
            }
        }
    }
    assert!(
        text.contains("Permission is hereby granted"),
        "the Bitstream Vera license text was not found in /usr/share/doc/fonts-dejavu-core/copyright"
    );
    out.push_str("Bitstream Vera Fonts Copyright\n------------------------------\n\n");
    out.push_str(&text);
    out
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let font = args
        .first()
        .cloned()
        .unwrap_or_else(|| "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf".into());
    let out_dir = PathBuf::from(
        args.get(1)
            .cloned()
            .unwrap_or_else(|| "svg-samples/glyphs".into()),
    );
    let data = std::fs::read(&font).unwrap_or_else(|e| panic!("{font}: {e}"));
    let face = ttf_parser::Face::parse(&data, 0).unwrap_or_else(|e| panic!("{font}: {e}"));
    let mut glyphs = Vec::new();
    for digit in '0'..='9' {
        let id = face
            .glyph_index(digit)
            .unwrap_or_else(|| panic!("{font}: no glyph for {digit:?}"));
        let mut o = Outline::default();
        let bb = face
            .outline_glyph(id, &mut o)
            .unwrap_or_else(|| panic!("{font}: no outline for {digit:?}"));
        glyphs.push((digit, o.cmds, bb));
    }
    // One scale for all: a square 1.2 times the largest extent, each digit centered.
    let extent = glyphs
        .iter()
        .map(|(_, _, b)| (b.x_max - b.x_min).max(b.y_max - b.y_min))
        .max()
        .expect("ten digits") as f32;
    let side = (1.2 * extent).round();
    std::fs::create_dir_all(&out_dir).unwrap_or_else(|e| panic!("{}: {e}", out_dir.display()));
    let mut csv = String::from("digit,contours,font_segments\n");
    for (digit, cmds, b) in &glyphs {
        let cx = 0.5 * (b.x_min as f32 + b.x_max as f32);
        let cy = -0.5 * (b.y_min as f32 + b.y_max as f32);
        let (x0, y0) = (cx - 0.5 * side, cy - 0.5 * side);
        let (d, contours, segments) = path_data(cmds);
        let svg = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"128\" height=\"128\" viewBox=\"{x0} {y0} {s} {s}\">\n  \
             <title>Digit {digit} of DejaVu Sans (font units, y down; see LICENSE.txt)</title>\n  \
             <rect id=\"background\" x=\"{x0}\" y=\"{y0}\" width=\"{s}\" height=\"{s}\" fill=\"#ffffff\"/>\n  \
             <path id=\"digit-{digit}\" fill=\"#000000\" d=\"{d}\"/>\n</svg>\n",
            x0 = num(x0),
            y0 = num(y0),
            s = num(side),
        );
        let file = out_dir.join(format!("{digit}.svg"));
        std::fs::write(&file, svg).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let _ = writeln!(csv, "{digit},{contours},{segments}");
        println!(
            "{}: {contours} contours, {segments} segments",
            file.display()
        );
    }
    let write = |name: &str, text: &str| {
        let f = out_dir.join(name);
        std::fs::write(&f, text).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        println!("{}", f.display());
    };
    write("segments.csv", &csv);
    write("LICENSE.txt", &license());
}
