//! Bode scenario files: inline ropes, laws, and the errors users see.
#![allow(clippy::float_cmp)] // parsed constants must come through bit for bit

use longreach_scenario::BodeScenario;

const BASE: &str = r#"
[rig]
rope = "dyneema2"
rope_length_m = 15.2
input_radius_m = 0.025
output_radius_m = 0.025
output_inertia_kg_m2 = 0.0284
output_damping_n_m_s = 0.05
[sweep]
mean_tensions_n = [100.0]
amplitude_deg = 4.5
frequencies_hz = [1.0, 2.0]
"#;

#[test]
fn shipped_scenarios_parse_with_the_papers_sweep() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios");
    for rope in ["dyneema2", "zylon2", "vectran2", "kevlar2", "stainless1"] {
        let s = BodeScenario::from_file(&dir.join(format!("bode_{rope}.toml"))).unwrap();
        let tensions: Vec<f64> = s.rigs.iter().map(|r| r.mean_tension_n).collect();
        assert_eq!(
            tensions,
            (1..=8).map(|i| 49.0 * f64::from(i)).collect::<Vec<_>>()
        );
        assert!((s.sine.amplitude_rad - 4.5f64.to_radians()).abs() < 1e-15);
        assert_eq!(s.sine.frequencies_hz.first(), Some(&0.1));
        assert_eq!(s.sine.frequencies_hz.last(), Some(&6.0));
        assert_eq!(s.rigs[0].rope_name, rope);
    }
}

#[test]
fn inline_rope_and_flory_law() {
    let text = r#"
[rig]
law = "flory"
rope_length_m = 15.2
input_radius_m = 0.025
output_radius_m = 0.025
output_inertia_kg_m2 = 0.0284
output_damping_n_m_s = 0.05
[rig.rope]
tensile_strength_n = 4000.0
k1 = 7.0e4
k3 = 9.0e5
c2 = 1.6e7
c3 = 1.5e6
kp = 3.0e4
[sweep]
mean_tensions_n = [100.0]
amplitude_deg = 4.5
frequencies_hz = [1.0, 2.0]
"#;
    let s = BodeScenario::from_str(text, "inline.toml").unwrap();
    let law = &s.rigs[0].law;
    assert_eq!(law.kp_n, Some(3.0e4));
    assert_eq!(law.kelvin[0].k_n, 9.0e5);
    assert!(s.rigs[0].rope_name.starts_with("inline"));
}

#[test]
fn errors_name_the_field_and_the_fix() {
    let cases = [
        (
            BASE.replace(
                "amplitude_deg = 4.5",
                "amplitude_deg = 4.5\namplitude_rad = 0.1",
            ),
            "exactly one of amplitude_rad and amplitude_deg",
        ),
        (
            BASE.replace("rope_length_m", "rope_lenght_m"),
            "unknown field `rope_lenght_m`",
        ),
        (
            BASE.replace(
                "rope = \"dyneema2\"",
                "rope = \"stainless1\"\nlaw = \"four_element\"",
            ),
            "four_element law needs `k3`",
        ),
        (
            BASE.replace("[1.0, 2.0]", "[1.0, 0.0]"),
            "sweep.frequencies_hz",
        ),
        (
            BASE.replace("mean_tensions_n = [100.0]", "mean_tensions_n = []"),
            "sweep.mean_tensions_n",
        ),
        (
            BASE.replace("rope = \"dyneema2\"", "rope = 3"),
            "expected a rope name or an inline table",
        ),
    ];
    for (text, expect) in cases {
        let err = BodeScenario::from_str(&text, "case.toml")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("case.toml") && err.contains(expect) && err.contains("fix:"),
            "{err}"
        );
    }
}

/// `[rig.relay_friction]` reaches the rig (slip rate defaulted); bad values name the
/// field, its line and the fix.
#[test]
fn relay_friction_section() {
    let with =
        |body: &str| BASE.replace("[sweep]", &format!("[rig.relay_friction]\n{body}\n[sweep]"));
    let s = BodeScenario::from_str(
        &with("coefficient = 0.02\ninertia_kg_m2 = 2e-5"),
        "relay.toml",
    )
    .unwrap();
    let f = s.rigs[0].relay_friction.unwrap();
    assert_eq!(f.coefficient, 0.02);
    assert_eq!(f.inertia_kg_m2, 2e-5);
    assert_eq!(
        f.slip_rate_rad_s,
        longreach_drive::RelayFriction::DEFAULT_SLIP_RATE_RAD_S
    );
    // BASE has no relay_friction: ideal pulleys.
    assert!(BodeScenario::from_str(BASE, "base.toml").unwrap().rigs[0]
        .relay_friction
        .is_none());
    for (body, field, line) in [
        (
            "coefficient = 1.5\ninertia_kg_m2 = 2e-5",
            "rig.relay_friction.coefficient",
            "relay.toml:10",
        ),
        (
            "coefficient = 0.01\ninertia_kg_m2 = -1.0",
            "rig.relay_friction.inertia_kg_m2",
            "relay.toml:11",
        ),
        (
            "coefficient = 0.01\ninertia_kg_m2 = 1e-5\nslip_rate_rad_s = 0.0",
            "rig.relay_friction.slip_rate_rad_s",
            "relay.toml:12",
        ),
    ] {
        let err = BodeScenario::from_str(&with(body), "relay.toml")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("relay.toml") && err.contains(field) && err.contains("fix:"),
            "{err}"
        );
        assert!(err.contains(line), "{err}");
    }
    let err = BodeScenario::from_str(&with("coefficent = 0.01\ninertia_kg_m2 = 1e-5"), "r.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("coefficent"), "{err}");
}
