//! Comparison with PyMUST 0.1.9 `smoothn` on reference cases written by
//! `bench/smoothn/pymust_reference.py` (inputs/outputs in tests/data, parameters in cases.json).
//!
//! * Fixed S, no robust weights, no missing data: the result is defined exactly, so both flavours
//!   must agree with PyMUST to rounding.
//! * Elsewhere PyMUST deviates from MATLAB (crate docs, "Faithful to MATLAB"): `Flavour::Pymust`
//!   reproduces PyMUST to rounding, which accounts for the whole difference, and the default
//!   (MATLAB) flavour differs by the sizes recorded below.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] functions
use serde_json::Value;
use sonoflow_regularise::testkit::*;
use sonoflow_regularise::{smoothn, Flavour, SmoothnParams, SmoothnReport};
use std::path::PathBuf;

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

struct Case {
    name: String,
    shape: Vec<usize>,
    components: usize,
    input: Vec<f64>,
    weights: Option<Vec<f64>>,
    pymust: Vec<f64>,
    pymust_s: f64,
    params: SmoothnParams,
}

impl Case {
    fn run(&self, flavour: Flavour) -> (Vec<f64>, SmoothnReport) {
        let p = SmoothnParams { flavour, ..self.params.clone() };
        smoothn(&self.input, &self.shape, self.components, self.weights.as_deref(), &p).unwrap()
    }
}

fn cases() -> Vec<Case> {
    let meta: Value = serde_json::from_str(&std::fs::read_to_string(data_dir().join("cases.json")).unwrap()).unwrap();
    meta["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let name = c["name"].as_str().unwrap().to_string();
            let load = |suffix: &str| read_npy(&data_dir().join(format!("{name}_{suffix}.npy"))).1;
            let params = SmoothnParams {
                s: c["s_given"].as_f64(),
                order: c["order"].as_u64().unwrap() as u32,
                robust: c["robust"].as_bool().unwrap(),
                spacing: c["spacing"].as_array().map(|a| a.iter().map(|v| v.as_f64().unwrap()).collect()),
                ..SmoothnParams::default()
            };
            Case {
                shape: c["shape"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect(),
                components: c["components"].as_u64().unwrap() as usize,
                input: load("in"),
                weights: c["weights"].as_bool().unwrap().then(|| load("w")),
                pymust: load("out"),
                pymust_s: c["s"].as_f64().unwrap(),
                params,
                name,
            }
        })
        .collect()
}

fn case(name: &str) -> Case {
    cases().into_iter().find(|c| c.name == name).unwrap_or_else(|| panic!("no case {name}"))
}

const EXACT: [&str; 5] = ["fixed_s_2d", "fixed_s_2d_order1", "fixed_s_2d_spacing", "fixed_s_1d", "fixed_s_3d"];

#[test]
fn reference_data_are_present_and_small() {
    let all = cases();
    assert_eq!(all.len(), 10);
    let bytes: u64 = std::fs::read_dir(data_dir()).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum();
    assert!(bytes < 1 << 20, "{bytes} bytes of reference data");
}

#[test]
fn fixed_s_without_robust_weights_agrees_with_pymust_to_rounding_in_both_flavours() {
    for name in EXACT {
        let c = case(name);
        for flavour in [Flavour::Matlab, Flavour::Pymust] {
            let (z, r) = c.run(flavour);
            // Orthonormal FFT-based DCT vs SciPy's pocketfft: measured nRMS ≤ 6e-16, max ≤ 1e-15.
            let e = nrms(&z, &c.pymust);
            assert!(e < 1e-13, "{name} {flavour:?}: nRMS {e:e}");
            assert_eq!(r.s, c.pymust_s);
        }
    }
}

#[test]
fn pymust_flavour_reproduces_pymust_where_it_deviates_from_matlab() {
    for name in ["robust_fixed_s", "auto_s", "robust_auto_s", "weighted_fixed_s"] {
        let c = case(name);
        let (z, r) = c.run(Flavour::Pymust);
        // Same algorithm, same branch decisions: measured nRMS ≤ 1e-14, S to 1e-15.
        let e = nrms(&z, &c.pymust);
        assert!(e < 1e-12, "{name}: nRMS {e:e}");
        assert!((r.s / c.pymust_s - 1.0).abs() < 1e-12, "{name}: S {} vs PyMUST {}", r.s, c.pymust_s);
    }
    // With missing values the nearest-neighbour fill of the initial guess breaks distance ties
    // differently from SciPy's `distance_transform_edt`; the iteration then converges (TolZ 1e-3)
    // from a slightly different start. Measured nRMS 4.5e-5, S 2.2008 vs 2.2002.
    let c = case("missing_robust_auto_s");
    let (z, r) = c.run(Flavour::Pymust);
    assert!(nrms(&z, &c.pymust) < 5e-4, "nRMS {:e}", nrms(&z, &c.pymust));
    assert!((r.s / c.pymust_s - 1.0).abs() < 0.01);
}

/// MATLAB flavour vs PyMUST: (case, measured nRMS, measured S ratio MATLAB/PyMUST, cause).
const DEVIATIONS: [(&str, f64, f64, &str); 5] = [
    ("robust_fixed_s", 1.39e-3, 1.0, "marginal vs global median of the residuals"),
    ("auto_s", 2.39e-3, 1.113, "S bounds with N = 2 and orthonormal-DCT GCV"),
    ("robust_auto_s", 2.26e-3, 0.964, "bounds, GCV normalisation, medians"),
    ("weighted_fixed_s", 9.46e-3, 1.0, "PyMUST stops after one iteration (z0 aliases z)"),
    ("missing_robust_auto_s", 3.04e-3, 0.955, "all of the above and the second component's initial guess"),
];

#[test]
fn matlab_flavour_differs_from_pymust_by_the_documented_amounts() {
    // The pymust-notes (§9) measured, on a 128×128×2 field with 10 % outliers: robust S = 10 nRMS
    // 1.0e-3; auto S 567 vs 754, nRMS 8.9e-3; robust auto S 72.1 vs 72.3, nRMS 3.7e-4. The 40×32×2
    // fields here give the same orders of magnitude (recorded in DEVIATIONS); the bracket ×/÷ 1.5
    // catches a deviation that disappears or grows.
    for (name, nrms_measured, s_ratio, cause) in DEVIATIONS {
        let c = case(name);
        let (z, r) = c.run(Flavour::Matlab);
        let e = nrms(&z, &c.pymust);
        assert!(
            e > nrms_measured / 1.5 && e < nrms_measured * 1.5,
            "{name} ({cause}): nRMS {e:.3e}, expected ~{nrms_measured:.2e}"
        );
        let ratio = r.s / c.pymust_s;
        assert!((ratio / s_ratio - 1.0).abs() < 0.01, "{name} ({cause}): S ratio {ratio:.4}, expected {s_ratio}");
    }
}

#[test]
fn weighted_difference_is_pymust_not_converging() {
    // The weighted solution is the fixed point (W + S L²) z = W y; tests/exact.rs checks that a tight
    // tolerance reaches it to 1e-13. At the default TolZ = 1e-3 ours is close to it; PyMUST's single
    // iteration is not (measured nRMS 3.1e-4 vs 9.6e-3).
    let c = case("weighted_fixed_s");
    let tight = SmoothnParams { tol_z: 1e-12, max_iter: 10_000, ..c.params.clone() };
    let (exact, r) = smoothn(&c.input, &c.shape, 1, c.weights.as_deref(), &tight).unwrap();
    assert!(r.converged);
    let (z, _) = c.run(Flavour::Matlab);
    let (ours, theirs) = (nrms(&z, &exact), nrms(&c.pymust, &exact));
    assert!(ours < 1e-3 && theirs > 20.0 * ours, "distance to the fixed point: ours {ours:.2e}, PyMUST {theirs:.2e}");
}
