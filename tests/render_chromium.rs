//! Every bundled kind of report renders in a real browser (issue 16): `vmt run` on the default scenario, a
//! lesson, the crawl and the 3-axis scenario, and `vmt study` on the study scenario write their HTML
//! reports; headless Chromium (Debian package `chromium`) then loads each page from disk and
//!
//! `vmt diagnose --report` on the lesson's recording is rendered and linted the same way.
//!
//! 1. parses it: `--dump-dom` serialises the DOM after parsing; it must hold every `<svg>`, `<figure>`,
//!    `<table>` and `<section>` of the file (an HTML parser drops or re-parents markup it cannot place,
//!    so a malformed page loses elements here);
//! 2. paints it: `--screenshot` must write a PNG of the requested size (the PNG IHDR chunk, bytes 16–23)
//!    whose bytes are not those of a blank page (a blank 1000 × H PNG compresses to a few kB).
//!
//! The screenshots are kept in `target/render/NAME.png` to look at; `docs/report.png` (the README's
//! picture) is `target/render/default.png`. Without chromium the test is skipped with a message on
//! stderr, except under CI (`CI` set), where `.ci/run` installs it and its absence is a failure.
//!
//! Each report also passes [`vmt_report::lint`] on the `report.json` written beside it: every figure
//! names both axes with units, every table column of bare numbers names its unit, no section is empty.

use crate::util::{self, root};
use std::path::{Path, PathBuf};
use std::process::Command;

const WIDTH: u32 = 1000;
const HEIGHT: u32 = 2400;

fn chromium() -> Option<PathBuf> {
    ["chromium", "chromium-browser", "google-chrome"].iter().find_map(|name| {
        let path = std::env::var_os("PATH")?;
        std::env::split_paths(&path).map(|d| d.join(name)).find(|p| p.is_file())
    })
}

fn vmt(args: &[&str]) {
    let out = util::vmt().args(args).output().expect("running vmt");
    // Exit 1 (an estimate missed its tolerance) still writes a report; 2 (bad input) does not.
    assert!(
        matches!(out.status.code(), Some(0) | Some(1)),
        "vmt {args:?} exited {:?}:\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Flags of a headless, offline, throw-away Chromium (fresh profile in `profile`).
fn chromium_cmd(browser: &Path, profile: &Path) -> Command {
    let mut c = Command::new(browser);
    c.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--hide-scrollbars",
    ])
    .arg(format!("--user-data-dir={}", profile.display()));
    c
}

fn count(html: &str, tag: &str) -> usize {
    html.matches(&format!("<{tag} ")).count() + html.matches(&format!("<{tag}>")).count()
}

/// Renders `page` and checks the parsed DOM and the screenshot; returns a problem or None.
fn render(browser: &Path, page: &Path, png: &Path) -> Result<(), String> {
    let source = std::fs::read_to_string(page).map_err(|e| format!("{}: {e}", page.display()))?;
    let url = format!("file://{}", page.canonicalize().unwrap().display());
    let profile = tempfile::tempdir().unwrap();
    let dom = chromium_cmd(browser, profile.path()).arg("--dump-dom").arg(&url).output().map_err(|e| e.to_string())?;
    if !dom.status.success() {
        return Err(format!(
            "chromium --dump-dom exited {:?}: {}",
            dom.status.code(),
            String::from_utf8_lossy(&dom.stderr)
        ));
    }
    let dom = String::from_utf8_lossy(&dom.stdout).to_string();
    for tag in ["svg", "figure", "table", "section", "h2"] {
        let (want, got) = (count(&source, tag), count(&dom, tag));
        if want != got {
            return Err(format!("{}: the file has {want} <{tag}> but Chromium parsed {got}", page.display()));
        }
    }
    if dom.contains("<parsererror") {
        return Err(format!("{}: Chromium reports a parser error", page.display()));
    }
    let profile = tempfile::tempdir().unwrap();
    let shot = chromium_cmd(browser, profile.path())
        .arg(format!("--screenshot={}", png.display()))
        .arg(format!("--window-size={WIDTH},{HEIGHT}"))
        .arg(&url)
        .output()
        .map_err(|e| e.to_string())?;
    if !shot.status.success() {
        return Err(format!(
            "chromium --screenshot exited {:?}: {}",
            shot.status.code(),
            String::from_utf8_lossy(&shot.stderr)
        ));
    }
    let bytes = std::fs::read(png).map_err(|e| format!("no screenshot {}: {e}", png.display()))?;
    if bytes.len() < 24 || &bytes[..8] != b"\x89PNG\r\n\x1a\n" {
        return Err(format!("{} is not a PNG", png.display()));
    }
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    if (w, h) != (WIDTH, HEIGHT) {
        return Err(format!("{}: screenshot is {w} × {h} px, expected {WIDTH} × {HEIGHT}", png.display()));
    }
    // A page of text, tables and plots compresses to well over 50 kB at this size (the default report's
    // first screen is ≈ 300 kB); a blank or error page to a few kB.
    if bytes.len() < 50_000 {
        return Err(format!("{}: screenshot only {} bytes: a blank page?", png.display(), bytes.len()));
    }
    Ok(())
}

#[test]
fn every_kind_of_report_renders_in_chromium_and_is_readable() {
    let root = root();
    let tmp = tempfile::tempdir().unwrap();
    let out = |name: &str| tmp.path().join(name);
    let sc = |rel: &str| root.join("scenarios").join(rel).display().to_string();
    let jobs: Vec<(&str, Vec<String>)> = vec![
        ("default", vec!["run".into(), sc("default.toml"), "--out".into(), out("default").display().to_string()]),
        (
            "lesson_backlash",
            vec![
                "run".into(),
                sc("lessons/backlash/scenario.toml"),
                "--out".into(),
                out("lesson").display().to_string(),
            ],
        ),
        ("crawl", vec!["run".into(), sc("crawl_seed002.toml"), "--out".into(), out("crawl").display().to_string()]),
        (
            "squareness_3axis",
            vec!["run".into(), sc("squareness_3axis.toml"), "--out".into(), out("3axis").display().to_string()],
        ),
        (
            "study",
            vec![
                "study".into(),
                sc("study_accel.toml"),
                "--vary".into(),
                "sensors.acc_z.noise_density=1e-7,1e-6,1e-5".into(),
                "--trials".into(),
                "20".into(),
                "-o".into(),
                out("study").display().to_string(),
            ],
        ),
    ];
    let dirs = ["default", "lesson", "crawl", "3axis", "study"];
    // The five commands run side by side (the default and the 3-axis scenario take ≈ 7 s each).
    std::thread::scope(|s| {
        for (_, args) in &jobs {
            s.spawn(move || vmt(&args.iter().map(String::as_str).collect::<Vec<_>>()));
        }
    });
    let mut problems: Vec<String> = Vec::new();
    for ((name, _), dir) in jobs.iter().zip(dirs) {
        let json = std::fs::read_to_string(out(dir).join("report.json")).expect("report.json beside report.html");
        let report: vmt_report::Report = serde_json::from_str(&json).expect("report.json holds a Report");
        problems.extend(vmt_report::lint(&report).into_iter().map(|p| format!("{name}: {p}")));
        assert!(
            report.sections.first().is_some_and(|s| s.heading == "Test conditions"),
            "{name}: the report must open with the test conditions"
        );
        if *name == "crawl" {
            // Every feed's velocity figure has a zoom where single readings show: four stick-slip cycles
            // of a crawling run, the first samples of a smooth one (at 80 mm/min the whole record is a
            // solid band 0.6 mm/min wide).
            let titles: Vec<&str> =
                report.sections.iter().flat_map(|s| s.figures.iter().map(|f| f.title.as_str())).collect();
            for feed in ["5", "20", "80"] {
                let zoom = format!("crawl at {feed} mm/min, zoom:");
                assert!(titles.iter().any(|t| t.starts_with(&zoom)), "crawl: no zoom at {feed} mm/min: {titles:?}");
            }
        }
    }
    // `vmt diagnose --report` on the lesson's recording, as a user would on their own data: the page is
    // written by the command; its data, built by the same library calls, pass the same lint.
    let model = root.join("scenarios/lessons/backlash/start_model.toml");
    let data = out("lesson").join("data");
    let diagnose_page = out("diagnose.html");
    vmt(&[
        "diagnose",
        "--model",
        &model.display().to_string(),
        "--data",
        &data.display().to_string(),
        "--report",
        &diagnose_page.display().to_string(),
    ]);
    {
        let m = vmt::model::read_model(&model).unwrap();
        let set = vmt::measurement::read_data(&data).unwrap();
        let cmp = vmt::modelcheck::compare(&m, &set, &data).unwrap();
        let d = vmt::modelcheck::diagnose(&m, &set, &data).unwrap();
        let report = vmt::report::model_check_report(&model, &data, &set, &cmp, Some(&d));
        problems.extend(vmt_report::lint(&report).into_iter().map(|p| format!("diagnose --report: {p}")));
        assert_eq!(report.sections[0].heading, "Test conditions");
        let titles: Vec<&str> =
            report.sections.iter().flat_map(|s| s.figures.iter().map(|f| f.title.as_str())).collect();
        for view in ["share of the residual each candidate explains", "by approach direction", "by position"] {
            assert!(titles.iter().any(|t| t.contains(view)), "diagnose --report lacks the {view} figure: {titles:?}");
        }
    }
    assert!(problems.is_empty(), "{} readability problems:\n{}", problems.len(), problems.join("\n"));

    let Some(browser) = chromium() else {
        assert!(std::env::var_os("CI").is_none(), "CI is set but chromium is not installed (.ci/run installs it)");
        eprintln!("SKIPPED: the Chromium render check (chromium not installed: apt-get install chromium)");
        return;
    };
    let shots = root.join("target/render");
    std::fs::create_dir_all(&shots).unwrap();
    // One page at a time: Chromium is heavy and the machine small (≈ 2.5 s per page).
    let results: Vec<Result<(), String>> = jobs
        .iter()
        .zip(dirs)
        .map(|((name, _), dir)| render(&browser, &out(dir).join("report.html"), &shots.join(format!("{name}.png"))))
        .collect();
    let failed: Vec<String> = results
        .into_iter()
        .chain(std::iter::once(render(&browser, &diagnose_page, &shots.join("diagnose.png"))))
        .filter_map(Result::err)
        .collect();
    assert!(failed.is_empty(), "render errors:\n{}", failed.join("\n"));
}
