use super::*;

/// A family whose fits are small solver runs: y = a·u (+ b·u² with the effect), so the
/// progress reports can be checked against the solver's own iteration counts.
struct Quadratic;

impl Family for Quadratic {
    fn plant(&self) -> Plant {
        Plant::Positioner
    }
    fn output(&self) -> &'static str {
        "pos_m"
    }
    fn formulation(&self) -> &'static str {
        "test"
    }
    fn effects(&self) -> &'static [&'static str] {
        &["square", "square-again"]
    }
    fn fit(&self, effects: &[&str], _parent: Option<&Fit>, _est: &Log, _val: &Log) -> Result<Fit, String> {
        let u: Vec<f64> = (0..200).map(|k| k as f64 / 100.0).collect();
        let y: Vec<f64> = u
            .iter()
            .map(|u| 2.0 * u + 0.5 * u * u + 0.01 * (u * 977.0).sin())
            .collect();
        let with_b = !effects.is_empty();
        let model = |x: &[f64], u: f64| x[0] * u + if with_b { x[1] * u * u } else { 0.0 };
        let r = crate::lsq::solve(
            |x: &[f64], out: &mut [f64]| {
                for (k, o) in out.iter_mut().enumerate() {
                    // Exponentiated so the fit is nonlinear and takes several iterations.
                    *o = model(&[x[0].exp(), x[1].exp()], u[k]) - y[k];
                }
                Ok(())
            },
            &[-2.0, -3.0],
            &[-10.0, -10.0],
            &[10.0, 10.0],
            u.len(),
            &crate::lsq::LsqOptions::default(),
        )
        .map_err(|e| e.to_string())?;
        let x = [r.x[0].exp(), r.x[1].exp()];
        let predicted = u.iter().map(|&u| model(&x, u)).collect();
        Ok(Fit::new(
            &Fit::label(effects),
            vec![("a".into(), x[0]), ("b".into(), x[1])],
            vec![None, None],
            y,
            predicted,
            r.iterations,
        ))
    }
    fn regressors<'a>(&self, _val: &'a Log) -> Vec<(String, Cow<'a, [f64]>)> {
        Vec::new()
    }
}

#[test]
fn progress_reports_every_fit_and_each_solver_iteration() {
    let log = crate::log::parse_log(
        "p.csv",
        "# plant: positioner\nt_s,force_N,pos_m\n0,0,0\n0.001,1,0\n",
        None,
    )
    .unwrap();
    let mut seen: Vec<(String, usize, usize, usize, f64)> = Vec::new();
    let d = diagnose(&Quadratic, &log, &log, false, &Rules::default(), &mut |p: &Progress| {
        seen.push((p.fit.to_string(), p.index, p.total, p.iteration, p.elapsed_s))
    })
    .unwrap();
    assert_eq!(d.cause, "square");
    // `square-again` was eligible in the first round too, so the second round tries it on
    // top of `square` (the floor stop does not override it): a fourth fit, the total
    // raised to 4 when that round starts.
    assert_eq!(d.rounds.len(), 1);
    let fits = [
        ("baseline", &d.baseline, 3),
        ("square", &d.candidates[0].fit, 3),
        ("square-again", &d.candidates[1].fit, 3),
        ("square+square-again", &d.rounds[0].candidates[0].fit, 4),
    ];
    for (i, (name, fit, total)) in fits.iter().enumerate() {
        let reports: Vec<usize> = seen.iter().filter(|s| s.1 == i + 1).map(|s| s.3).collect();
        assert!(seen
            .iter()
            .filter(|s| s.1 == i + 1)
            .all(|s| s.0 == *name && s.2 == *total));
        // The fit's start, then one report per solver iteration, counted up.
        let expected: Vec<usize> = (0..=fit.iterations).collect();
        assert!(fit.iterations > 2, "{name}: {} iterations", fit.iterations);
        assert_eq!(reports, expected, "{name}");
    }
    // In order of the fits, and time never runs backwards.
    assert!(seen.windows(2).all(|w| w[0].1 <= w[1].1 && w[0].4 <= w[1].4));
    assert_eq!(seen.len(), fits.iter().map(|f| f.1.iterations + 1).sum::<usize>());
}
