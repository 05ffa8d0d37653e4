//! `[payload]` of arm scenarios: a point mass on a link, in the statics, the gravity
//! feed-forward and the dynamics.

use std::path::Path;

use longreach_arm::run::run;
use longreach_arm::scenario::parse;
use longreach_arm::spec::STANDARD_GRAVITY_M_S2;
use longreach_arm::DrivenArm;

fn scenarios() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios")
}

const Q_RAD: [f64; 5] = [0.3, -0.2, 0.1, 0.2, -0.4];

/// The shipped longreach5 base step scenario at the pose `Q_RAD`, with `payload` (a
/// `[payload]` table or nothing) and `duration_s`.
fn scenario(payload: &str, duration_s: f64, hold: bool) -> DrivenArm {
    let mut text = std::fs::read_to_string(scenarios().join("arm_dyneema2_base_step.toml"))
        .unwrap()
        .replace("duration_s = 10.0", &format!("duration_s = {duration_s}"))
        .replace(
            "tip_frame = \"tip\"",
            &format!("tip_frame = \"tip\"\ninitial_q_rad = {Q_RAD:?}"),
        );
    if hold {
        text = text.replace(
            "command = { kind = \"step\", to_rad = 0.1, at_s = 0.5 }",
            "",
        );
    }
    text.push_str(payload);
    parse(&text, "payload test", &scenarios())
        .unwrap_or_else(|e| panic!("{e}"))
        .arm
}

fn rope_torques(arm: &DrivenArm) -> Vec<f64> {
    let phi: Vec<f64> = arm
        .static_pairs(arm.initial_q_rad())
        .iter()
        .map(|s| s.phi_n)
        .collect();
    arm.routing().transpose_apply(&phi)
}

#[test]
fn static_rope_torques_carry_the_payload_weight_times_its_lever_arm() {
    let (m, off) = (3.0, [0.1, 0.0, 0.05]);
    let with = scenario(
        &format!("\n[payload]\nmass_kg = {m}\nlink = \"tip\"\noffset_m = {off:?}\n"),
        1.0,
        true,
    );
    let without = scenario("", 1.0, true);
    let (tw, t0) = (rope_torques(&with), rope_torques(&without));
    // By hand: planar chain pitching about +y, joints 2.6, 2.4, 2.2, 2.0 m apart, tip
    // 1.8 m beyond j5 (robots/longreach5). Rotation about y by phi maps (x, z) to
    // (x cos phi + z sin phi, -x sin phi + z cos phi). The joint must hold
    // -(r x F) . y = -m g (x_payload - x_joint).
    let lengths = [2.6, 2.4, 2.2, 2.0];
    let mut phi = 0.0;
    let mut x_joint = [0.0; 5];
    for k in 0..5 {
        phi += Q_RAD[k];
        if k < 4 {
            x_joint[k + 1] = x_joint[k] + lengths[k] * phi.cos();
        }
    }
    let x_payload = x_joint[4] + (1.8 + off[0]) * phi.cos() + off[2] * phi.sin();
    for k in 0..5 {
        let hand = -m * STANDARD_GRAVITY_M_S2 * (x_payload - x_joint[k]);
        let got = tw[k] - t0[k];
        println!("j{}: {got:.6} N*m, by hand {hand:.6} N*m", k + 1);
        assert!(
            (got - hand).abs() <= 1e-6 * hand.abs(),
            "j{}: {got} vs {hand}",
            k + 1
        );
    }
    // The feed-forward holds the heavier arm where it was put: 1 s of holding moves the
    // joints only by the fibre ropes' creep (4e-5 rad at j1); without the payload in the
    // feed-forward the j5 servo alone would have to find 56 N*m (0.6 rad of error).
    let mut st = with.initial_state();
    for _ in 0..1000 {
        with.step(&mut st).unwrap();
    }
    for j in 0..5 {
        assert!(
            (st.q_rad[j] - Q_RAD[j]).abs() < 1e-3,
            "j{}: {}",
            j + 1,
            st.q_rad[j]
        );
    }
}

#[test]
fn tip_sag_grows_with_the_payload() {
    // Held for 3 s at the pose: the fibre ropes creep under their static load, the
    // motors hold their angles, the tip sinks; a heavier payload sinks it further.
    let mut sags = Vec::new();
    for m in [0.0, 4.0, 8.0] {
        let arm = scenario(
            &format!("\n[payload]\nmass_kg = {m}\nlink = \"tip\"\n"),
            3.0,
            true,
        );
        let z0 = arm.tip_m(arm.initial_q_rad()).unwrap().z;
        let (trace, metrics) = run(&arm, 3.0, 100, 1.0, &mut |_, _| {}).unwrap();
        let zc = trace.columns.iter().position(|c| c == "tip_z_m").unwrap();
        let z1 = trace.rows[trace.rows.len() - 1][zc];
        println!(
            "payload {m} kg: tip sank {:.4} mm (tip error {:.4} mm)",
            1e3 * (z0 - z1),
            1e3 * metrics.tip_error_m
        );
        assert!(z1 < z0, "the tip rose: {z0} -> {z1}");
        sags.push(z0 - z1);
    }
    assert!(sags[1] > sags[0] && sags[2] > sags[1], "{sags:?}");
}

#[test]
fn bad_payloads_name_file_line_and_field() {
    let base = std::fs::read_to_string(scenarios().join("arm_dyneema2_base_step.toml")).unwrap();
    for (table, field, needle) in [
        (
            "[payload]\nmass_kg = -1.0\n",
            "payload.mass_kg",
            "mass_kg = -1",
        ),
        (
            "[payload]\nmass_kg = 1.0\nlink = \"nope\"\n",
            "payload.link",
            "no link named 'nope'",
        ),
        (
            "[payload]\nmass_kg = 1.0\nlink = \"base\"\n",
            "payload.link",
            "base",
        ),
        (
            "[payload]\nmass_kg = 1.0\noffset_m = [0.0, 1.0]\n",
            "",
            "offset_m",
        ),
        ("[payload]\nmass = 1.0\n", "", "mass"),
    ] {
        let text = format!("{base}\n{table}");
        let e = parse(&text, "pay.toml", &scenarios()).unwrap_err();
        let msg = e.to_string();
        println!("{msg}");
        assert!(msg.contains("pay.toml") && msg.contains(needle), "{msg}");
        if !field.is_empty() {
            assert_eq!(e.field, field, "{msg}");
            let line = base.lines().count() + 3 + usize::from(field == "payload.link");
            assert_eq!(e.line, Some(line), "{msg}");
        }
    }
}

#[test]
fn static_safety_factor_is_taken_at_the_rest_the_run_starts_from() {
    // The largest rope tension at rest, from the statics: at the commanded pose for a
    // payload the servos know of (the arm rests on its command), at the sagged pose for
    // 8 kg they are not told of (`payload_mass`: the run starts where the statics put
    // the joints, not on the command).
    let strength = |arm: &DrivenArm| arm.pairs()[0].spec.rope.tensile_strength_n;
    let largest = |arm: &DrivenArm, q: &[f64]| -> Vec<f64> {
        arm.static_pairs(q)
            .iter()
            .map(|s| s.f_pos_n.max(s.f_neg_n))
            .collect()
    };
    let known = scenario(
        "\n[payload]\nmass_kg = 8.0\nlink = \"tip\"\noffset_m = [0.1, 0.0, 0.0]\n",
        0.01,
        true,
    );
    let unknown = scenario(
        "\n[payload]\nmass_kg = 0.0\nlink = \"tip\"\noffset_m = [0.1, 0.0, 0.0]\n\
         [[effect]]\nname = \"payload_mass\"\nparams = [8.0]\n",
        0.01,
        true,
    );
    let sagged = unknown.initial_state().q_rad.clone();
    let sag = sagged
        .iter()
        .zip(Q_RAD)
        .fold(0.0f64, |a, (q, c)| a.max((q - c).abs()));
    assert!(sag > 1e-4, "the unknown payload sags the arm: {sag}");
    // At the commanded pose (the former figure) the statics would differ by more than
    // the test's tolerance.
    let moved = largest(&unknown, &Q_RAD)
        .iter()
        .zip(largest(&unknown, &sagged[..5]))
        .fold(0.0f64, |a, (c, s)| a.max((c / s - 1.0).abs()));
    println!(
        "sag {sag:.3e} rad ({:?}); the largest static tension moves by {moved:.2e} with it",
        &sagged[..5]
    );
    assert!(moved > 1e-5, "{moved}");
    for (arm, q, what) in [
        (&known, Q_RAD.to_vec(), "known"),
        (&unknown, sagged[..5].to_vec(), "unknown"),
    ] {
        let (_, m) = run(arm, 0.01, 10, 0.005, &mut |_, _| {}).unwrap();
        for (p, f) in m.pairs.iter().zip(largest(arm, &q)) {
            let want = strength(arm) / f;
            println!(
                "{what} {}: {:.6} by the statics {want:.6}",
                p.joint, p.static_safety_factor
            );
            assert!(
                (p.static_safety_factor / want - 1.0).abs() < 1e-6,
                "{what} {}: {} vs {want}",
                p.joint,
                p.static_safety_factor
            );
        }
    }
}
