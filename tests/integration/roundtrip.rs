//! SVG in → out → in renders the same.

use diffsvg::metrics::compare;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::{Scene, Sizing};

use super::common::samples;

#[test]
fn samples_survive_a_round_trip() {
    for path in samples() {
        let a = Scene::load(&path, Sizing::Natural).unwrap();
        let text = a.to_svg_string();
        let b = Scene::from_svg_str(&text, "roundtrip.svg", Sizing::Natural).unwrap_or_else(|e| {
            panic!("{}: written SVG does not load: {e}\n{text}", path.display())
        });
        assert_eq!(a.path_count(), b.path_count(), "{}", path.display());
        let opts = RenderOptions::default();
        let c = compare(&render(&a, &opts), &render(&b, &opts));
        // Numbers are written with 4 decimals (and stroke frames as transforms, whose
        // coordinates are rescaled): differences stay within a couple of levels at an edge.
        assert!(
            c.max < 2.0 && c.mae < 0.01,
            "{}: round trip changed pixels by {:?}",
            path.display(),
            c
        );
        // Ids survive.
        let ids = |s: &Scene| {
            let mut v = Vec::new();
            s.for_each_path(|p| v.push(p.id.clone()));
            v
        };
        assert_eq!(ids(&a), ids(&b), "{}", path.display());
    }
}
