//! The HTML reports (issue #15.6) in a real browser: `diagnose --report` and `run --report`
//! write one self-contained page each; headless Chromium loads it without console errors, and
//! its DOM shows the verdict first, the plots inline and the parameters.
//!
//! Chromium is Debian's `chromium` (tools/test.sh installs it when missing). Without it the
//! tests skip with a message, unless HIL_REQUIRE_CHROMIUM is set (test.sh sets it).
use std::path::{Path, PathBuf};
use std::process::Command;

use hil_host::generate;
use hil_host::log::Plant;

fn chromium() -> Option<PathBuf> {
    for name in ["chromium", "chromium-browser", "google-chrome"] {
        for dir in std::env::var("PATH").unwrap_or_default().split(':') {
            let p = Path::new(dir).join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    if std::env::var_os("HIL_REQUIRE_CHROMIUM").is_some() {
        panic!(
            "HIL_REQUIRE_CHROMIUM is set but no chromium is on PATH: run tools/test.sh (it installs Debian's chromium)"
        );
    }
    eprintln!("SKIP: no chromium on PATH (apt-get install chromium)");
    None
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hil-report-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Chromium headless on `page` with `extra` arguments; returns (stdout, stderr).
fn browse(chrome: &Path, dir: &Path, page: &Path, extra: &[&str]) -> (String, String) {
    let profile = dir.join(format!("profile-{}", extra.len()));
    let o = Command::new(chrome)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--hide-scrollbars",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(format!("file://{}", page.display()))
        .output()
        .expect("chromium runs");
    assert!(
        o.status.success(),
        "chromium failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// The page's checks common to both reports: self-contained, no console errors, a screenshot.
fn check_page(chrome: &Path, dir: &Path, page: &Path) -> String {
    let html = std::fs::read_to_string(page).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    for external in ["<script", "<link", "src=\"http", "href=\"http", "url(http", "@import"] {
        assert!(!html.contains(external), "the page refers outside itself: `{external}`");
    }
    let (_, log) = browse(chrome, dir, page, &["--enable-logging=stderr", "--v=0", "--dump-dom"]);
    for bad in ["Uncaught", "ERROR:CONSOLE", "CONSOLE(", "Failed to load resource"] {
        assert!(!log.contains(bad), "console error `{bad}`:\n{log}");
    }
    let shot = dir.join("page.png");
    browse(
        chrome,
        dir,
        page,
        &["--window-size=1200,1800", &format!("--screenshot={}", shot.display())],
    );
    let png = std::fs::read(&shot).unwrap();
    assert!(
        png.starts_with(b"\x89PNG") && png.len() > 20_000,
        "screenshot {} bytes",
        png.len()
    );
    let (dom, _) = browse(chrome, dir, page, &["--dump-dom"]);
    dom
}

#[test]
fn diagnose_report_loads_in_chromium_and_shows_the_verdict_first() {
    let Some(chrome) = chromium() else { return };
    let dir = scratch("diagnose");
    let case = generate::generate(Plant::Evvt, "supply-voltage", 11).unwrap();
    std::fs::write(dir.join("estimation.csv"), &case.estimation_csv).unwrap();
    std::fs::write(dir.join("validation.csv"), &case.validation_csv).unwrap();
    let page = dir.join("report.html");
    let o = Command::new(env!("CARGO_BIN_EXE_hil-host"))
        .arg("diagnose")
        .arg(dir.join("estimation.csv"))
        .arg("--validation")
        .arg(dir.join("validation.csv"))
        .arg("--report")
        .arg(&page)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dom = check_page(&chrome, &dir, &page);
    // The verdict is the first thing after the title, and names the hidden effect.
    let verdict = dom.find("id=\"verdict\"").expect("a verdict block");
    let first_h2 = dom.find("<h2").expect("sections");
    assert!(verdict < first_h2, "the verdict comes before the evidence");
    let block = &dom[verdict..first_h2];
    assert!(block.contains("supply-voltage") && block.contains("% gain"), "{block}");
    // The plots are inline SVG, with time in seconds on the fit plot.
    assert!(dom.matches("<svg").count() >= 4, "inline plots");
    assert!(dom.contains("time (s)"));
    // The parameters with their confidence.
    assert!(
        dom.contains("<th>± 95 %</th>") && dom.contains("alpha_rel_slope_per_V"),
        "parameters table"
    );
}

#[test]
fn run_report_loads_in_chromium_with_every_actuator_and_the_fault_markers() {
    let Some(chrome) = chromium() else { return };
    let dir = scratch("run");
    let scenario = dir.join("sag.toml");
    std::fs::write(
        &scenario,
        "name = \"short-sag\"\nduration_s = 0.6\n[[fault]]\nkind = \"battery_sag\"\nstart_s = 0.2\nend_s = 0.45\nu_batt_v = 8.0\n",
    )
    .unwrap();
    let page = dir.join("run.html");
    let o = Command::new(env!("CARGO_BIN_EXE_hil-host"))
        .arg("run")
        .arg(&scenario)
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--report")
        .arg(&page)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dom = check_page(&chrome, &dir, &page);
    assert!(dom.contains("id=\"verdict\"") && dom.contains("faults injected: battery_sag"));
    for plot in ["evvt", "vacuum", "vacuum-hpt", "vacuum-hpc", "ehvva", "ehvva-crank"] {
        assert!(dom.contains(&format!("id=\"plot-{plot}\"")), "plot {plot} missing");
    }
    // The sag's start and end are marked and keyed.
    assert!(dom.contains("0.20 s injected battery_sag") && dom.contains("0.45 s battery_sag ends"));
}
