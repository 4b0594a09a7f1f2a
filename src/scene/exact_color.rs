//! Colors written exactly.
//!
//! SVG's color syntax, as usvg reads it, has 8 bits per channel, so a fitted color such as
//! `0.41372` would come back as `106/255 = 0.41569`. The writer therefore adds the exact
//! channels beside any color that 8 bits do not hold: `data-fill-rgb="r g b"` and
//! `data-stroke-rgb` on a shape (which then always has an `id`), `data-rgb` on a gradient
//! stop (its gradient always has one), each channel in `[0, 1]` as the shortest decimal
//! that reads back to the same `f64`. Every other reader ignores the attributes and sees
//! the 8-bit color. The reader takes an exact color only where its 8-bit rounding is the
//! color the element shows, so a color edited by hand afterwards wins.

use std::collections::HashMap;

use super::{Paint, Scene};

/// The attribute of a shape's exact fill color.
pub(crate) const FILL: &str = "data-fill-rgb";
/// The attribute of a shape's exact stroke color.
pub(crate) const STROKE: &str = "data-stroke-rgb";
/// The attribute of a gradient stop's exact color.
pub(crate) const STOP: &str = "data-rgb";

/// A channel as 8 bits, as the color syntax writes it.
pub(crate) fn byte(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Whether 8 bits hold `c` exactly.
pub(crate) fn is_8bit(c: &[f64; 3]) -> bool {
    c.iter().all(|&v| byte(v) as f64 / 255.0 == v)
}

/// The attribute text ` NAME="r g b"` for `c`, or nothing when 8 bits hold it.
pub(crate) fn attribute(name: &str, c: &[f64; 3]) -> String {
    if is_8bit(c) {
        return String::new();
    }
    let v = c.map(|v| format!("{}", v.clamp(0.0, 1.0)));
    format!(" {name}=\"{}\"", v.join(" "))
}

fn parse(value: &str) -> Option<[f64; 3]> {
    let mut it = value
        .split_ascii_whitespace()
        .map(|v| v.parse::<f64>().ok());
    let c = [it.next()??, it.next()??, it.next()??];
    (it.next().is_none() && c.iter().all(|v| (0.0..=1.0).contains(v))).then_some(c)
}

/// `exact` if it rounds to the 8-bit color `shown`, else `shown` stays.
fn take(shown: &mut [f64; 3], exact: Option<[f64; 3]>) {
    if let Some(e) = exact
        && e.map(byte) == shown.map(byte)
    {
        *shown = e;
    }
}

/// Puts the exact colors that `text` (the SVG the scene was read from) carries back into
/// `scene`. Text without the attributes costs a search.
pub(crate) fn restore(scene: &mut Scene, text: &str) {
    if !text.contains(FILL) && !text.contains(STROKE) && !text.contains(STOP) {
        return;
    }
    let Ok(doc) = usvg::roxmltree::Document::parse(text) else {
        return;
    };
    let mut shapes: HashMap<&str, [Option<[f64; 3]>; 2]> = HashMap::new();
    let mut stops: HashMap<&str, Vec<Option<[f64; 3]>>> = HashMap::new();
    for n in doc.descendants().filter(|n| n.is_element()) {
        let Some(id) = n.attribute("id") else {
            continue;
        };
        let fill = n.attribute(FILL).and_then(parse);
        let stroke = n.attribute(STROKE).and_then(parse);
        if fill.is_some() || stroke.is_some() {
            shapes.insert(id, [fill, stroke]);
        }
        let own: Vec<_> = n
            .children()
            .filter(|c| c.has_tag_name("stop"))
            .map(|c| c.attribute(STOP).and_then(parse))
            .collect();
        if own.iter().any(Option::is_some) {
            stops.insert(id, own);
        }
    }
    let restore_paint = |paint: &mut Paint, exact: Option<[f64; 3]>| match paint {
        Paint::Solid(c) => take(c, exact),
        Paint::Gradient(g) => {
            if let Some(s) = stops.get(g.id.as_str())
                && s.len() == g.stops.len()
            {
                for (stop, e) in g.stops.iter_mut().zip(s) {
                    take(&mut stop.color, *e);
                }
            }
        }
        Paint::Image(_) => {}
    };
    scene.for_each_path_mut(|p| {
        let [fill, stroke] = shapes.get(p.id.as_str()).copied().unwrap_or([None, None]);
        if let Some(f) = &mut p.fill {
            restore_paint(&mut f.paint, fill);
        }
        if let Some(s) = &mut p.stroke {
            restore_paint(&mut s.paint, stroke);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Sizing;

    #[test]
    fn colors_survive_a_round_trip_through_svg() {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
            <linearGradient id="g" x2="1"><stop offset="0" stop-color="red"/>
              <stop offset="1" stop-color="blue"/></linearGradient>
            <path d="M1 1 L9 1 L5 8 Z" fill="#336699" stroke="#000" stroke-width="2"/>
            <rect id="r" x="10" y="10" width="8" height="8" fill="url(#g)"/></svg>"##;
        let mut s = Scene::from_svg_str(svg, "c.svg", Sizing::Natural).unwrap();
        let layout = super::super::ParamLayout::new(&s);
        let mut v = s.params();
        let colors: Vec<usize> = (0..v.len())
            .filter(|&i| layout.slots[i].group == super::super::ParamGroup::Color)
            .collect();
        assert_eq!(colors.len(), 3 + 3 + 2 * 3);
        for (k, &i) in colors.iter().enumerate() {
            v[i] = (0.1 + 0.0731 * k as f64).min(1.0);
        }
        s.set_params(&v);
        let text = s.to_svg_string();
        let back = Scene::from_svg_str(&text, "b.svg", Sizing::Natural).unwrap();
        let w = back.params();
        for &i in &colors {
            assert_eq!(w[i], v[i], "slot {i}\n{text}");
        }
        // A color edited by hand (its 8 bits changed) is the edited one.
        let c = colors[..3].iter().map(|&i| byte(v[i]));
        let shown: String = c.map(|b| format!("{b:02x}")).collect();
        let edited = text.replacen(&format!("fill=\"#{shown}\""), "fill=\"#ff0000\"", 1);
        assert_ne!(edited, text, "{text}");
        let e = Scene::from_svg_str(&edited, "e.svg", Sizing::Natural).unwrap();
        assert_eq!(e.params()[colors[0]], 1.0);
    }
}
