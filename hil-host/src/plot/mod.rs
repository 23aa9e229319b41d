//! SVG plots drawn with `plotters` (its SVG backend; text as SVG `<text>` elements, so no
//! system fonts are needed): time axes in seconds with round ticks, one y axis per unit
//! (stacked panels sharing the time axis), legends in a column right of the data, numbered
//! markers for faults and mode changes with their key in that column.

use std::fs;
use std::path::{Path, PathBuf};

use plotters::prelude::*;

mod diagnosis;
mod run;

pub use diagnosis::{diagnosis_plots, diagnosis_plots_timed, diagnosis_svgs};
pub use run::{run_markers, run_svgs};

/// One line: label (empty: not in the legend), colour (`#rrggbb` or a basic name), points.
pub struct Series<'a> {
    pub label: &'a str,
    pub colour: &'a str,
    pub x: &'a [f64],
    pub y: &'a [f64],
}

/// One panel: one y axis with one unit, its series, dashed references (`hlines`), and an
/// optional shaded band `±band` (a confidence band).
pub struct Panel<'a> {
    /// The axis title with its unit, e.g. `phase (crank deg)`.
    pub y_label: &'a str,
    pub series: Vec<Series<'a>>,
    pub hlines: Vec<f64>,
    pub band: Option<f64>,
}

/// A vertical marker through every panel at `x` (a fault, a mode change).
#[derive(Clone, Debug, PartialEq)]
pub struct Marker {
    pub x: f64,
    pub label: String,
    /// `#rrggbb` or a basic name.
    pub colour: &'static str,
}

/// At most this many points per series are drawn (min/max kept per bucket, so peaks survive).
const MAX_POINTS: usize = 4000;
/// Drawing size: plot width, legend column, panel height.
const PLOT_W: u32 = 820;
const LEGEND_W: u32 = 250;
const PANEL_H: u32 = 190;
const TITLE_H: u32 = 34;
const MAX_MARKER_KEYS: usize = 14;

fn thin(x: &[f64], y: &[f64]) -> Vec<(f64, f64)> {
    let n = x.len().min(y.len());
    if n <= MAX_POINTS {
        return (0..n).map(|i| (x[i], y[i])).collect();
    }
    let bucket = n.div_ceil(MAX_POINTS / 2);
    let mut out = Vec::with_capacity(MAX_POINTS + 2);
    for start in (0..n).step_by(bucket) {
        let end = (start + bucket).min(n);
        let (mut lo, mut hi) = (start, start);
        for i in start..end {
            if y[i] < y[lo] {
                lo = i;
            }
            if y[i] > y[hi] {
                hi = i;
            }
        }
        let (a, b) = if lo < hi { (lo, hi) } else { (hi, lo) };
        out.push((x[a], y[a]));
        if b != a {
            out.push((x[b], y[b]));
        }
    }
    out
}

/// A colour from `#rrggbb` or a basic name (unknown: grey).
fn colour(c: &str) -> RGBColor {
    let hex = |s: &str| u8::from_str_radix(s, 16).ok();
    if let Some(h) = c.strip_prefix('#') {
        if let (6, Some(r), Some(g), Some(b)) = (
            h.len(),
            h.get(0..2).and_then(hex),
            h.get(2..4).and_then(hex),
            h.get(4..6).and_then(hex),
        ) {
            return RGBColor(r, g, b);
        }
    }
    match c {
        "black" => RGBColor(0, 0, 0),
        "red" => RGBColor(214, 39, 40),
        "blue" => RGBColor(31, 119, 180),
        "green" => RGBColor(44, 160, 44),
        "orange" => RGBColor(255, 127, 14),
        "purple" => RGBColor(148, 103, 189),
        _ => RGBColor(127, 127, 127),
    }
}

/// Decimals that show a tick step of `span / 8` without noise digits.
fn decimals(span: f64) -> usize {
    let step = span / 8.0;
    if !(step > 0.0) || !step.is_finite() {
        return 2;
    }
    (-step.log10().floor()).clamp(0.0, 9.0) as usize
}

/// A tick label: `dec` decimals; values within float noise of zero (relative to the axis
/// `span`) are 0.
fn tick(v: f64, dec: usize, span: f64) -> String {
    let v = if v.abs() < 1e-9 * span { 0.0 } else { v };
    if v != 0.0 && (v.abs() >= 1e6 || v.abs() < 1e-4) {
        format!("{v:.2e}")
    } else {
        let s = format!("{v:.dec$}");
        if s.starts_with("-") && s.trim_start_matches(['-', '0', '.']).is_empty() {
            s[1..].to_string()
        } else {
            s
        }
    }
}

fn range_of(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !(lo <= hi) {
        return (0.0, 1.0);
    }
    if hi - lo <= f64::EPSILON * hi.abs().max(1.0) {
        let d = if hi == 0.0 { 1.0 } else { 0.05 * hi.abs() };
        return (lo - d, hi + d);
    }
    (lo, hi)
}

/// An SVG document with one panel: the old single-axis call (`run` and the tests use it).
pub fn line_plot(title: &str, x_label: &str, y_label: &str, series: &[Series], hlines: &[f64]) -> String {
    let panel = Panel {
        y_label,
        series: series
            .iter()
            .map(|s| Series {
                label: s.label,
                colour: s.colour,
                x: s.x,
                y: s.y,
            })
            .collect(),
        hlines: hlines.to_vec(),
        band: None,
    };
    panel_plot(title, x_label, &[panel], &[])
}

/// An SVG document: stacked panels sharing the x axis (labelled on the bottom panel), the
/// legend of each panel beside it, markers through all panels numbered on the top one with
/// their key under the legends.
pub fn panel_plot(title: &str, x_label: &str, panels: &[Panel], markers: &[Marker]) -> String {
    match draw_panels(title, x_label, panels, markers) {
        Ok(svg) => svg,
        // Drawing into a string does not fail in practice; if it does, say so in the picture.
        Err(e) => format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"600\" height=\"60\"><text x=\"10\" y=\"30\">{}: plot failed: {}</text></svg>\n",
            escape(title),
            escape(&e)
        ),
    }
}

fn draw_panels(title: &str, x_label: &str, panels: &[Panel], markers: &[Marker]) -> Result<String, String> {
    let n = panels.len().max(1) as u32;
    let (w, h) = (PLOT_W + LEGEND_W, TITLE_H + n * PANEL_H + 24);
    let pts: Vec<Vec<Vec<(f64, f64)>>> = panels
        .iter()
        .map(|p| p.series.iter().map(|s| thin(s.x, s.y)).collect())
        .collect();
    let (x0, x1) = range_of(pts.iter().flatten().flatten().map(|p| p.0));
    let xdec = decimals(x1 - x0);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let root = root.titled(title, ("sans-serif", 17)).map_err(e)?;
        let (plot_area, legend_area) = root.split_horizontally(PLOT_W);
        let rows = plot_area.split_evenly((panels.len().max(1), 1));
        let font = ("sans-serif", 14).into_font();
        let small = ("sans-serif", 13).into_font();
        let mut legend_y = 14;
        for (i, ((area, panel), pts)) in rows.iter().zip(panels).zip(&pts).enumerate() {
            let last = i + 1 == panels.len();
            let mut ys: Vec<f64> = pts.iter().flatten().map(|p| p.1).collect();
            ys.extend(&panel.hlines);
            if let Some(b) = panel.band {
                ys.extend([b, -b]);
            }
            let (y0, y1) = range_of(ys.into_iter());
            let pad = 0.06 * (y1 - y0);
            let (y0, y1) = (y0 - pad, y1 + pad);
            let ydec = decimals(y1 - y0);
            let mut chart = ChartBuilder::on(area)
                .margin_top(if i == 0 { 14 } else { 6 })
                .margin_right(12)
                .x_label_area_size(if last { 44 } else { 18 })
                .y_label_area_size(78)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(e)?;
            let xfmt = |v: &f64| tick(*v, xdec, x1 - x0);
            let yfmt = |v: &f64| tick(*v, ydec, y1 - y0);
            let mut mesh = chart.configure_mesh();
            mesh.x_labels(10)
                .y_labels(6)
                .x_label_formatter(&xfmt)
                .y_label_formatter(&yfmt)
                .y_desc(panel.y_label)
                .label_style(font.clone())
                .axis_desc_style(font.clone())
                .bold_line_style(RGBColor(225, 225, 225))
                .light_line_style(TRANSPARENT);
            if last {
                mesh.x_desc(x_label);
            }
            mesh.draw().map_err(e)?;
            if let Some(b) = panel.band {
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(x0, -b), (x1, b)],
                        RGBColor(31, 119, 180).mix(0.12).filled(),
                    )))
                    .map_err(e)?;
            }
            for &v in &panel.hlines {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(x0, v), (x1, v)],
                        RGBColor(136, 136, 136).stroke_width(1),
                    )))
                    .map_err(e)?;
            }
            for m in markers {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(m.x, y0), (m.x, y1)],
                        colour(m.colour).mix(0.8).stroke_width(1),
                    )))
                    .map_err(e)?;
            }
            if i == 0 {
                for (k, m) in markers.iter().enumerate() {
                    chart
                        .draw_series(std::iter::once(Text::new(
                            format!("{}", k + 1),
                            (m.x, y1),
                            small.clone().color(&colour(m.colour)),
                        )))
                        .map_err(e)?;
                }
            }
            for (s, p) in panel.series.iter().zip(pts) {
                let c = colour(s.colour);
                chart
                    .draw_series(LineSeries::new(
                        p.iter().copied().filter(|(x, y)| x.is_finite() && y.is_finite()),
                        c.stroke_width(1),
                    ))
                    .map_err(e)?;
            }
            // This panel's legend beside it, at its top.
            legend_y = legend_y.max(i as i32 * PANEL_H as i32 + 14);
            if panel.series.iter().any(|s| !s.label.is_empty()) {
                legend_area
                    .draw(&Text::new(panel.y_label.to_string(), (8, legend_y), small.clone()))
                    .map_err(e)?;
                legend_y += 16;
            }
            for s in panel.series.iter().filter(|s| !s.label.is_empty()) {
                legend_area
                    .draw(&PathElement::new(
                        vec![(10, legend_y + 6), (32, legend_y + 6)],
                        colour(s.colour).stroke_width(2),
                    ))
                    .map_err(e)?;
                legend_area
                    .draw(&Text::new(s.label.to_string(), (38, legend_y), font.clone()))
                    .map_err(e)?;
                legend_y += 17;
            }
            legend_y += 8;
        }
        if !markers.is_empty() {
            legend_area
                .draw(&Text::new("markers".to_string(), (8, legend_y), small.clone()))
                .map_err(e)?;
            legend_y += 16;
            for (k, m) in markers.iter().enumerate().take(MAX_MARKER_KEYS) {
                legend_area
                    .draw(&Text::new(
                        format!("{} {}", k + 1, m.label),
                        (10, legend_y),
                        small.clone().color(&colour(m.colour)),
                    ))
                    .map_err(e)?;
                legend_y += 15;
            }
            if markers.len() > MAX_MARKER_KEYS {
                legend_area
                    .draw(&Text::new(
                        format!("... and {} more", markers.len() - MAX_MARKER_KEYS),
                        (10, legend_y),
                        small.clone(),
                    ))
                    .map_err(e)?;
            }
        }
        root.present().map_err(e)?;
    }
    // The confidence band's rectangles carry a class, for styling and for tests.
    Ok(svg.replace(
        "opacity=\"0.12\" fill=\"#1F77B4\"",
        "class=\"band\" opacity=\"0.12\" fill=\"#1F77B4\"",
    ))
}

fn escape(t: &str) -> String {
    t.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

const RED: &str = "#d62728";
const BLUE: &str = "#1f77b4";
const GREEN: &str = "#2ca02c";
const PURPLE: &str = "#9467bd";
const ORANGE: &str = "#ff7f0e";

fn write_all(svgs: Vec<(String, String)>, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    for (name, svg) in svgs {
        let p = dir.join(name);
        // Whole files only (crate::output): a killed run leaves the old plot or none.
        crate::output::write_atomic(&p, svg.as_bytes())?;
        written.push(p);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_the_extremes() {
        let x: Vec<f64> = (0..100_000).map(|i| i as f64).collect();
        let mut y = vec![0.0; 100_000];
        y[54_321] = 7.0;
        y[9_999] = -3.0;
        let t = thin(&x, &y);
        assert!(t.len() <= MAX_POINTS + 2);
        assert!(t.iter().any(|&(_, v)| v == 7.0) && t.iter().any(|&(_, v)| v == -3.0));
    }

    #[test]
    fn svg_is_well_formed_and_escapes_text() {
        let s = line_plot(
            "a < b & c",
            "x",
            "y",
            &[Series {
                label: "l",
                colour: "red",
                x: &[0.0, 1.0],
                y: &[1.0, f64::NAN],
            }],
            &[0.5],
        );
        assert!(s.starts_with("<svg") && s.trim_end().ends_with("</svg>"));
        assert!(s.contains("a &lt; b &amp; c"), "{s}");
    }

    /// The x ticks of a 0..2.7 s time axis are round numbers of seconds, the legend is right
    /// of the data (x beyond the plot width), and two panels have their own y axis titles.
    #[test]
    fn time_ticks_are_round_and_legends_sit_outside_the_data() {
        let t: Vec<f64> = (0..=270).map(|k| k as f64 * 0.01).collect();
        let y: Vec<f64> = t.iter().map(|t| (7.0 * t).sin()).collect();
        let v: Vec<f64> = t.iter().map(|t| 12.0 + t).collect();
        let s = panel_plot(
            "two units",
            "time (s)",
            &[
                Panel {
                    y_label: "lift (mm)",
                    series: vec![Series {
                        label: "lift",
                        colour: BLUE,
                        x: &t,
                        y: &y,
                    }],
                    hlines: vec![],
                    band: None,
                },
                Panel {
                    y_label: "battery (V)",
                    series: vec![Series {
                        label: "battery",
                        colour: RED,
                        x: &t,
                        y: &v,
                    }],
                    hlines: vec![],
                    band: Some(0.5),
                },
            ],
            &[Marker {
                x: 1.234,
                label: "1.23 s fault".into(),
                colour: RED,
            }],
        );
        let texts: Vec<(f64, String)> = s
            .split("<text")
            .skip(1)
            .filter_map(|chunk| {
                let x = chunk.split("x=\"").nth(1)?.split('"').next()?.parse::<f64>().ok()?;
                let body = chunk.split('>').nth(1)?.split('<').next()?.trim().to_string();
                Some((x, body))
            })
            .collect();
        for label in ["lift", "battery"] {
            let (x, _) = texts.iter().find(|(_, b)| b == label).expect(label);
            assert!(*x > f64::from(PLOT_W), "legend `{label}` at x = {x}, inside the plot");
        }
        for tick in ["0.5", "1.0", "1.5", "2.0", "2.5"] {
            assert!(texts.iter().any(|(_, b)| b == tick), "no tick {tick}");
        }
        assert!(
            !texts.iter().any(|(_, b)| b.len() > 6 && b.parse::<f64>().is_ok()),
            "noisy tick"
        );
        assert!(texts.iter().any(|(_, b)| b == "lift (mm)") && texts.iter().any(|(_, b)| b == "battery (V)"));
        assert!(texts.iter().any(|(_, b)| b == "1 1.23 s fault"));
        assert_eq!(s.matches("class=\"band\"").count(), 1, "the ±0.5 band");
    }
}
