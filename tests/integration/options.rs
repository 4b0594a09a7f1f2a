//! Issue 28: an option is bounded once, in the library. Each formerly drifted option of
//! `tests/drifted-options.tsv` is refused by the command line with the library's message,
//! named as its flag (Python's test reads the same table and expects the keyword).

use super::common::{assert_fails, diffsvg, root, s, scratch, write};
use diffsvg::Image;

/// `(command, option, value, message)` rows of the shared table.
pub fn drifted_options() -> Vec<[String; 4]> {
    let text = std::fs::read_to_string(root().join("tests/drifted-options.tsv")).unwrap();
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!(f.len(), 4, "four columns: {l}");
            [f[0], f[1], f[2], f[3]].map(str::to_string)
        })
        .collect()
}

#[test]
fn drifted_options_are_refused_with_the_librarys_message() {
    let dir = scratch("drifted-options");
    let png = dir.join("t.png");
    Image::filled(16, 16, [0.2, 0.4, 0.6, 1.0])
        .save_png(&png)
        .unwrap();
    let glyph = write(
        &dir,
        "g.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="16" height="16"><rect x="4" y="4" width="8" height="8"/></svg>"#,
    );
    let rows = drifted_options();
    assert!(rows.len() >= 6);
    for [command, option, value, message] in rows {
        let flag = format!("--{}", option.replace('_', "-"));
        let out = dir.join(format!("{command}-{option}.out"));
        let mut args: Vec<String> = match command.as_str() {
            "vectorize" => vec![
                "vectorize".into(),
                s(&png).into(),
                "-o".into(),
                format!("{}.svg", s(&out)),
            ],
            // Options are checked before the digit files are read.
            "digits" => vec![
                "digits".into(),
                "--images".into(),
                "none.idx".into(),
                "-o".into(),
                s(&out).into(),
            ],
            "glyphs" => vec![
                "glyphs".into(),
                s(&glyph).into(),
                "-o".into(),
                s(&out).into(),
            ],
            c => panic!("unknown command {c}"),
        };
        args.push(flag.clone());
        args.push(value.clone());
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = diffsvg(&args);
        let expected = format!("{flag} {value} {message}");
        assert_fails(&o, &expected, "", &out);
    }
}
