//! `vmt compare` and `vmt diagnose` read an ISO 230-2 `.dat` file (the ecmc key=value format of
//! ../shared/realdata/ecmc_iso230_2/) directly as `--data`, as they read a measurement set.

use crate::util::{self, realdata};

fn vmt(args: &[&str]) -> (i32, String, String) {
    let out = util::vmt().args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn compare_and_diagnose_take_an_iso230_2_dat_file_as_data() {
    let Some(dir) = realdata::realdata("ecmc_iso230_2", "compare_and_diagnose_take_an_iso230_2_dat_file_as_data")
    else {
        return;
    };
    let dat = dir.join("ess_target_muts_logger/b02_x_target_x.md_ISO230.dat");
    let tmp = tempfile::tempdir().unwrap();
    let empty = tmp.path().join("empty.toml");
    std::fs::write(&empty, "format = \"vmt-model/1\"\naxis = \"x\"\n").unwrap();
    let (m, d) = (empty.to_str().unwrap(), dat.to_str().unwrap());
    let (code, out, err) = vmt(&["diagnose", "--model", m, "--data", d, "--json"]);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    let ranking = j["ranking"].as_array().unwrap();
    assert!(!ranking.is_empty() && j["normalized_rms"].as_f64().unwrap() > 0.0);
    // The loop's first step on this test (a 33 µm raw residual) finds something significant.
    let best = ranking.iter().find(|r| r["verdict"] == "significant").expect("a significant candidate");
    let name = best["effect"].as_str().unwrap();
    let added = tmp.path().join("m1.toml");
    let (code, _, err) =
        vmt(&["add", "--model", m, "--effect", name, "--from-diagnosis", "--data", d, "-o", added.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let rms = |model: &str| {
        let (code, out, err) = vmt(&["compare", "--model", model, "--data", d, "--json"]);
        assert_eq!(code, 0, "{err}");
        let j: serde_json::Value = serde_json::from_str(&out).unwrap();
        j["channels"][0]["rms"].as_f64().unwrap()
    };
    let (before, after) = (rms(m), rms(added.to_str().unwrap()));
    eprintln!("b02_x: + {name}: residual RMS {:.2} → {:.2} µm", before * 1e6, after * 1e6);
    assert!(after < before);
    // A .dat file that is not one: exit 2, the file named.
    let bad = tmp.path().join("bad.dat");
    std::fs::write(&bad, "this is not an ISO 230-2 file\n").unwrap();
    let (code, _, err) = vmt(&["compare", "--model", m, "--data", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("bad.dat"), "{err}");
}
