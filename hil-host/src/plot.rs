//! Plain SVG line plots: no dependencies, readable in any browser, diffable as text.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use crate::diagnose::Diagnosis;
use crate::residuals::autocorrelation;

/// One line: label, colour, (x, y) points.
pub struct Series<'a> {
    pub label: &'a str,
    pub colour: &'a str,
    pub x: &'a [f64],
    pub y: &'a [f64],
}

/// At most this many points per series are drawn (min/max kept per bucket, so peaks survive).
const MAX_POINTS: usize = 4000;

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

/// An SVG document with the series, axes labels and a legend; `hlines` are dashed references.
pub fn line_plot(title: &str, x_label: &str, y_label: &str, series: &[Series], hlines: &[f64]) -> String {
    let (w, h, ml, mr, mt, mb) = (900.0, 420.0, 70.0, 20.0, 40.0, 50.0);
    let pts: Vec<Vec<(f64, f64)>> = series.iter().map(|s| thin(s.x, s.y)).collect();
    let all = pts.iter().flatten();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all {
        if x.is_finite() && y.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    for &v in hlines {
        y0 = y0.min(v);
        y1 = y1.max(v);
    }
    if x0 >= x1 {
        x1 = x0 + 1.0;
    }
    if y0 >= y1 {
        y1 = y0 + 1.0;
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let sx = |x: f64| ml + (x - x0) / (x1 - x0) * (w - ml - mr);
    let sy = |y: f64| mt + (1.0 - (y - y0) / (y1 - y0)) * (h - mt - mb);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="22" font-size="15" text-anchor="middle">{}</text>"#,
        w / 2.0,
        escape(title)
    );
    let _ = writeln!(
        s,
        r#"<rect x="{ml}" y="{mt}" width="{}" height="{}" fill="none" stroke="black"/>"#,
        w - ml - mr,
        h - mt - mb
    );
    for k in 0..=4 {
        let fx = x0 + (x1 - x0) * k as f64 / 4.0;
        let fy = y0 + (y1 - y0) * k as f64 / 4.0;
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{}" text-anchor="middle">{}</text>"#,
            sx(fx),
            h - mb + 16.0,
            tick(fx)
        );
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{:.1}" text-anchor="end">{}</text>"#,
            ml - 4.0,
            sy(fy) + 4.0,
            tick(fy)
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        w / 2.0,
        h - 10.0,
        escape(x_label)
    );
    let _ = writeln!(
        s,
        r#"<text x="16" y="{}" text-anchor="middle" transform="rotate(-90 16 {})">{}</text>"#,
        h / 2.0,
        h / 2.0,
        escape(y_label)
    );
    for &v in hlines {
        let _ = writeln!(
            s,
            r##"<line x1="{ml}" x2="{}" y1="{:.1}" y2="{:.1}" stroke="#888" stroke-dasharray="5,4"/>"##,
            w - mr,
            sy(v),
            sy(v)
        );
    }
    for (i, (ser, p)) in series.iter().zip(&pts).enumerate() {
        let mut d = String::new();
        for (k, &(x, y)) in p.iter().filter(|(x, y)| x.is_finite() && y.is_finite()).enumerate() {
            let _ = write!(d, "{}{:.1},{:.1} ", if k == 0 { "M" } else { "L" }, sx(x), sy(y));
        }
        let _ = writeln!(
            s,
            r#"<path d="{d}" fill="none" stroke="{}" stroke-width="1.2"/>"#,
            ser.colour
        );
        let ly = mt + 14.0 + 16.0 * i as f64;
        let _ = writeln!(
            s,
            r#"<line x1="{}" x2="{}" y1="{ly}" y2="{ly}" stroke="{}" stroke-width="2"/>"#,
            w - mr - 170.0,
            w - mr - 150.0,
            ser.colour
        );
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}">{}</text>"#,
            w - mr - 145.0,
            ly + 4.0,
            escape(ser.label)
        );
    }
    s.push_str("</svg>\n");
    s
}

fn tick(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e5) {
        format!("{v:.2e}")
    } else {
        format!("{v:.3}")
    }
}

fn escape(t: &str) -> String {
    t.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// Writes the diagnosis plots into `dir`: measured vs baseline vs extended, the residuals, the
/// residual autocorrelation with its 99 % band and the baseline residual's cross-correlation
/// with the (up to three) regressors it is most correlated with, with the same band. Returns
/// the files written.
pub fn diagnosis_plots(d: &Diagnosis, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    fs::create_dir_all(dir)?;
    let n = d.baseline.measured.len();
    let k: Vec<f64> = (0..n).map(|i| i as f64).collect();
    let ext_label = format!("extended ({})", d.cause);
    let mut written = Vec::new();
    let mut put = |name: &str, svg: String| -> std::io::Result<()> {
        let p = dir.join(name);
        crate::output::write_atomic(&p, svg.as_bytes())?;
        written.push(p);
        Ok(())
    };
    put(
        "fit.svg",
        line_plot(
            &format!("{}: {} on validation data", d.plant, d.output),
            "validation sample",
            &d.output,
            &[
                Series {
                    label: "measured",
                    colour: "black",
                    x: &k,
                    y: &d.baseline.measured,
                },
                Series {
                    label: "baseline",
                    colour: "#d62728",
                    x: &k,
                    y: &d.baseline.predicted,
                },
                Series {
                    label: &ext_label,
                    colour: "#1f77b4",
                    x: &k,
                    y: &d.extended.predicted,
                },
            ],
            &[],
        ),
    )?;
    let rb = d.baseline.residual();
    let re = d.extended.residual();
    put(
        "residuals.svg",
        line_plot(
            "residuals on validation data",
            "validation sample",
            &d.output,
            &[
                Series {
                    label: "baseline",
                    colour: "#d62728",
                    x: &k,
                    y: &rb,
                },
                Series {
                    label: &ext_label,
                    colour: "#1f77b4",
                    x: &k,
                    y: &re,
                },
            ],
            &[0.0],
        ),
    )?;
    let lags = d.whiteness.lags;
    let lag_x: Vec<f64> = (0..=lags).map(|l| l as f64).collect();
    let ab = autocorrelation(&rb, lags);
    let ae = autocorrelation(&re, lags);
    put(
        "autocorrelation.svg",
        line_plot(
            "residual autocorrelation with the 99 % band",
            "lag (samples)",
            "normalised autocorrelation",
            &[
                Series {
                    label: "baseline",
                    colour: "#d62728",
                    x: &lag_x,
                    y: &ab,
                },
                Series {
                    label: &ext_label,
                    colour: "#1f77b4",
                    x: &lag_x,
                    y: &ae,
                },
            ],
            &[d.whiteness.band, -d.whiteness.band],
        ),
    )?;
    // The residual's correlation with the regressors it is most correlated with.
    let mut worst: Vec<&crate::residuals::CrossCheck> = d.cross.iter().filter(|c| !c.correlation.is_empty()).collect();
    worst.sort_by(|a, b| (b.max_abs / b.band).total_cmp(&(a.max_abs / a.band)));
    worst.truncate(3);
    if let Some(first) = worst.first() {
        let half = (first.correlation.len() / 2) as f64;
        let lag_x: Vec<f64> = (0..first.correlation.len()).map(|i| i as f64 - half).collect();
        let colours = ["#d62728", "#2ca02c", "#9467bd"];
        let series: Vec<Series> = worst
            .iter()
            .zip(colours)
            .map(|(c, colour)| Series {
                label: &c.name,
                colour,
                x: &lag_x[..c.correlation.len().min(lag_x.len())],
                y: &c.correlation,
            })
            .collect();
        put(
            "cross_correlation.svg",
            line_plot(
                "baseline residual cross-correlation with the 99 % band (most correlated regressors)",
                "lag (samples; positive: the signal leads the residual)",
                "normalised cross-correlation",
                &series,
                &[first.band, -first.band],
            ),
        )?;
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
        assert!(s.contains("a &lt; b &amp; c"));
    }
}
