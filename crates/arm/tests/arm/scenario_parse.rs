//! Arm scenario files: defaults, effects from the registry, routes, errors.

use std::path::Path;

use longreach_arm::scenario::parse;

fn robots() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../robots"))
}

const BASE: &str = r#"
[arm]
urdf = "arm5/arm5.urdf"
[sim]
dt_s = 0.001
duration_s = 1.0
[transmission_defaults]
rope = "dyneema2"
joint_radius_m = 0.025
preload_n = 2000.0
motor = { mode = "kinematic" }
[[transmission]]
joint = "q1"
[[transmission]]
joint = "q2"
"#;

#[test]
fn defaults_route_and_lengths_come_from_the_geometry() {
    let sc = parse(BASE, "base.toml", robots()).unwrap();
    let arm = &sc.arm;
    assert_eq!(arm.pairs().len(), 2);
    // Pair 2 runs over the relay at q1 (r = 25 mm): row [0.025, 0.025, 0, 0, 0].
    assert_eq!(arm.routing().row(1), &[0.025, 0.025, 0.0, 0.0, 0.0]);
    // Rope length: 0.5 m motor offset + 2 m link (MuJoCo anchor L_2 = 2.5 m).
    assert!((arm.pairs()[1].spec.length_m - 2.5).abs() < 1e-12);
    assert_eq!(arm.pairs()[1].spec.span_lengths_m.len(), 2);
}

#[test]
fn effects_from_the_registry_change_the_law() {
    let text = BASE.replace(
        "[[transmission]]\njoint = \"q2\"",
        "[[transmission]]\njoint = \"q2\"\neffects = [{ name = \"internal_damping\" }]",
    );
    let sc = parse(&text, "fx.toml", robots()).unwrap();
    let (a, b) = (&sc.arm.pairs()[0].spec, &sc.arm.pairs()[1].spec);
    assert_eq!(b.effects, vec!["internal_damping".to_string()]);
    assert!(a.law != b.law, "the effect did not change the law");
    let bad = BASE.replace(
        "[[transmission]]\njoint = \"q2\"",
        "[[transmission]]\njoint = \"q2\"\neffects = [{ name = \"relay_frictionx\" }]",
    );
    let err = parse(&bad, "fx.toml", robots()).unwrap_err().to_string();
    assert!(
        err.contains("unknown effect 'relay_frictionx'") && err.contains("internal_damping"),
        "{err}"
    );
}

#[test]
fn errors_name_line_field_and_fix() {
    let bad = BASE.replace("joint = \"q2\"", "joint = \"q2\"\ntensioner = \"spring\"");
    let err = parse(&bad, "t.toml", robots()).unwrap_err();
    assert_eq!(err.field, "transmission.1.tensioner");
    assert_eq!(err.line, Some(16));
    assert!(err.fix.contains("constant_force"));
    let bad = BASE.replace("preload_n = 2000.0", "preload_n = 2000.0\nspeed = 3");
    let err = parse(&bad, "t.toml", robots()).unwrap_err().to_string();
    assert!(err.contains("unknown field `speed`"), "{err}");
    // A relay at a joint that is not proximal.
    let bad = BASE.replace(
        "joint = \"q1\"",
        "joint = \"q1\"\nroute = [{ joint = \"q2\", radius_m = 0.02 }]",
    );
    let err = parse(&bad, "t.toml", robots()).unwrap_err().to_string();
    assert!(err.contains("not proximal"), "{err}");
}

#[test]
fn csv_command_is_read_and_interpolated() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("ref.csv"),
        "time_s,angle_rad\n0.0,0.0\n1.0,0.2\n2.0,0.2\n",
    )
    .unwrap();
    let urdf = robots().join("arm5/arm5.urdf");
    let text = BASE
        .replace(
            "urdf = \"arm5/arm5.urdf\"",
            &format!("urdf = {:?}", urdf.display().to_string()),
        )
        .replace(
            "joint = \"q2\"",
            "joint = \"q2\"\ncommand = { kind = \"csv\", file = \"ref.csv\" }",
        );
    let sc = parse(&text, "csv.toml", dir.path()).unwrap();
    let c = &sc.arm.commands()[1];
    assert!((c.angle_rad(0.0, 0.5) - 0.1).abs() < 1e-12);
    assert!((c.angle_rad(0.0, 3.0) - 0.2).abs() < 1e-12);
    let bad = text.replace("ref.csv", "missing.csv");
    let err = parse(&bad, "csv.toml", dir.path()).unwrap_err();
    assert_eq!(err.field, "transmission.1.command.file");
}
