//! The diagnosis plots: measured against modelled output, residuals, their correlations.

use std::path::{Path, PathBuf};

use super::*;
use crate::diagnose::Diagnosis;
use crate::residuals::autocorrelation;

/// The diagnosis plots as (file name, SVG): measured, baseline and extended output; the
/// residuals (the extended model's is the remainder); the residual autocorrelation with its
/// 99 % band; the baseline residual's cross-correlation with the (up to three) regressors it
/// is most correlated with, with the same band. `t_s` is the validation data's time when it
/// has one sample per output sample; otherwise the x axis is the validation sample.
pub fn diagnosis_svgs(d: &Diagnosis, t_s: Option<&[f64]>) -> Vec<(String, String)> {
    let n = d.baseline.measured.len();
    let index: Vec<f64> = (0..n).map(|i| i as f64).collect();
    let (x, x_label): (Vec<f64>, String) = match t_s {
        Some(t) if t.len() == n => (t.to_vec(), "time (s)".into()),
        // The fit decimated or trimmed the data: its samples have no one-to-one time.
        Some(t) => (
            index,
            format!(
                "sample of the fit ({n} from {} validation samples: decimated or trimmed)",
                t.len()
            ),
        ),
        None => (index, "validation sample".into()),
    };
    let x_label = x_label.as_str();
    let causes = if d.cause == "none" {
        "no effect".to_string()
    } else {
        d.cause.clone()
    };
    let ext_label = format!("extended ({causes})");
    let out_label = format!("{} (validation)", d.output);
    let mut svgs = Vec::new();
    svgs.push((
        "fit.svg".to_string(),
        panel_plot(
            &format!("{}: {} on validation data", d.plant, d.output),
            x_label,
            &[Panel {
                y_label: &out_label,
                series: vec![
                    Series {
                        label: "measured",
                        colour: "black",
                        x: &x,
                        y: &d.baseline.measured,
                    },
                    Series {
                        label: "baseline",
                        colour: RED,
                        x: &x,
                        y: &d.baseline.predicted,
                    },
                    Series {
                        label: &ext_label,
                        colour: BLUE,
                        x: &x,
                        y: &d.extended.predicted,
                    },
                ],
                hlines: vec![],
                band: None,
            }],
            &[],
        ),
    ));
    let rb = d.baseline.residual();
    let re = d.extended.residual();
    let res_label = format!("residual {}", d.output);
    svgs.push((
        "residuals.svg".to_string(),
        panel_plot(
            "residuals on validation data (the extended model's is the remainder)",
            x_label,
            &[
                Panel {
                    y_label: &res_label,
                    series: vec![Series {
                        label: "baseline",
                        colour: RED,
                        x: &x,
                        y: &rb,
                    }],
                    hlines: vec![0.0],
                    band: None,
                },
                Panel {
                    y_label: &res_label,
                    series: vec![Series {
                        label: "remainder (extended)",
                        colour: BLUE,
                        x: &x,
                        y: &re,
                    }],
                    hlines: vec![0.0],
                    band: None,
                },
            ],
            &[],
        ),
    ));
    let lags = d.whiteness.lags;
    let lag_x: Vec<f64> = (0..=lags).map(|l| l as f64).collect();
    let ab = autocorrelation(&rb, lags);
    let ae = autocorrelation(&re, lags);
    svgs.push((
        "autocorrelation.svg".to_string(),
        panel_plot(
            "residual autocorrelation (shaded: the 99 % band of white noise)",
            "lag (samples)",
            &[Panel {
                y_label: "autocorrelation (normalised)",
                series: vec![
                    Series {
                        label: "baseline",
                        colour: RED,
                        x: &lag_x,
                        y: &ab,
                    },
                    Series {
                        label: &ext_label,
                        colour: BLUE,
                        x: &lag_x,
                        y: &ae,
                    },
                ],
                hlines: vec![0.0],
                band: Some(d.whiteness.band),
            }],
            &[],
        ),
    ));
    let mut worst: Vec<&crate::residuals::CrossCheck> = d.cross.iter().filter(|c| !c.correlation.is_empty()).collect();
    worst.sort_by(|a, b| (b.max_abs / b.band).total_cmp(&(a.max_abs / a.band)));
    worst.truncate(3);
    if let Some(first) = worst.first() {
        let half = (first.correlation.len() / 2) as f64;
        let lag_x: Vec<f64> = (0..first.correlation.len()).map(|i| i as f64 - half).collect();
        let series: Vec<Series> = worst
            .iter()
            .zip([RED, GREEN, PURPLE])
            .map(|(c, colour)| Series {
                label: &c.name,
                colour,
                x: &lag_x[..c.correlation.len().min(lag_x.len())],
                y: &c.correlation,
            })
            .collect();
        svgs.push((
            "cross_correlation.svg".to_string(),
            panel_plot(
                "baseline residual cross-correlation with the most correlated regressors (shaded: 99 % band)",
                "lag (samples; positive: the signal leads the residual)",
                &[Panel {
                    y_label: "cross-correlation (normalised)",
                    series,
                    hlines: vec![0.0],
                    band: Some(first.band),
                }],
                &[],
            ),
        ));
    }
    svgs
}

/// Writes [`diagnosis_svgs`] into `dir` against the validation sample index; returns the files.
pub fn diagnosis_plots(d: &Diagnosis, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    write_all(diagnosis_svgs(d, None), dir)
}

/// Writes [`diagnosis_svgs`] into `dir` against the validation data's time `t_s`.
pub fn diagnosis_plots_timed(d: &Diagnosis, t_s: &[f64], dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    write_all(diagnosis_svgs(d, Some(t_s)), dir)
}
