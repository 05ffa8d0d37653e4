//! Flexible links (crates/arm/src/flex.rs): a cantilever against the beam's closed
//! forms, the stiff limit against the rigid arm, energy, and the modes of the
//! linearised arm against the rig's transfer function and a simulated response.

use crate::common;

use common::{kinematic, rig_pair, robot_path, uniform_pairs};
use longreach_arm::modes::modes;
use longreach_arm::transmission::Tensioner;
use longreach_arm::{
    load_urdf, parse_urdf, scenario, tube_ei_n_m2, Command, DrivenArm, FlexDynamics, FlexLinkSpec,
};
use longreach_drive::tf::rig_resonance;
use longreach_drive::RigSpec;
use longreach_rope::{Catalog, LawKind, RopeLaw};
use nalgebra::Vector3;
use std::path::Path;

// A 10 m CFRP tube, OD 200 mm, ID 190 mm, E = 110 GPa, 1600 kg/m^3.
const L: f64 = 10.0;
const E: f64 = 110e9;
const OD: f64 = 0.2;
const ID: f64 = 0.19;
const RHO: f64 = 1600.0;

fn mu() -> f64 {
    RHO * std::f64::consts::PI * (OD * OD - ID * ID) / 4.0
}

/// One tube on a joint about the vertical: gravity bends it out of the joint's plane
/// (clamped there), the joint turns it freely in the plane.
fn cantilever_urdf() -> String {
    let m = mu() * L;
    format!(
        r#"<robot name="cantilever">
  <link name="base"/>
  <link name="tube">
    <inertial><origin xyz="{c} 0 0"/><mass value="{m}"/>
      <inertia ixx="1e-6" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/></inertial>
  </link>
  <joint name="j1" type="continuous">
    <parent link="base"/><child link="tube"/><origin xyz="0 0 0"/><axis xyz="0 0 1"/>
    <dynamics damping="0"/>
  </joint>
  <link name="tip"/>
  <joint name="tip_fixed" type="fixed">
    <parent link="tube"/><child link="tip"/><origin xyz="{L} 0 0"/>
  </joint>
</robot>"#,
        c = L / 2.0,
        i = m * L * L / 12.0,
    )
}

fn cantilever(modes: usize, tip_mass_kg: f64, zeta: f64) -> DrivenArm {
    let mut spec = parse_urdf(&cantilever_urdf(), "cantilever").unwrap();
    if tip_mass_kg > 0.0 {
        spec.add_payload("tip", tip_mass_kg, Vector3::zeros())
            .unwrap();
    }
    DrivenArm::new(spec, vec![], vec![Command::Hold], vec![0.0], 1e-3)
        .unwrap()
        .with_flexible_links(vec![FlexLinkSpec {
            link: 1,
            ei_n_m2: tube_ei_n_m2(E, OD, ID),
            damping_ratio: zeta,
            modes,
            mass_per_length_kg_m: Some(mu()),
        }])
        .unwrap()
}

fn tip_z(arm: &DrivenArm) -> f64 {
    let st = arm.initial_state();
    arm.tip_m(&st.q_rad).unwrap().z
}

#[test]
fn cantilever_sags_as_the_beam_formulas_say() {
    let ei = tube_ei_n_m2(E, OD, ID);
    let w = mu() * 9.81;
    let own = w * L.powi(4) / (8.0 * ei);
    let p_kg = 20.0;
    let tip = p_kg * 9.81 * L.powi(3) / (3.0 * ei);
    for modes in [1, 2, 3, 4] {
        let z0 = -tip_z(&cantilever(modes, 0.0, 0.0));
        // The tip load alone by superposition (the model is linear in the load).
        let zp = -tip_z(&cantilever(modes, p_kg, 0.0)) - z0;
        println!(
            "{modes} modes: own weight {z0:.6} m vs w L^4/8EI {own:.6} m ({:+.3}%), tip load {zp:.6} m vs P L^3/3EI {tip:.6} m ({:+.3}%)",
            100.0 * (z0 / own - 1.0),
            100.0 * (zp / tip - 1.0)
        );
        if modes >= 2 {
            assert!(
                (z0 / own - 1.0).abs() < 5e-3,
                "{modes} modes: own weight {z0} vs {own}"
            );
        }
        if modes >= 3 {
            assert!(
                (zp / tip - 1.0).abs() < 5e-3,
                "{modes} modes: tip load {zp} vs {tip}"
            );
        }
    }
}

#[test]
fn cantilever_released_straight_settles_on_the_static_sag() {
    // Released straight at rest, damped: it rings and comes to rest on the sag.
    let arm = cantilever(2, 0.0, 0.05);
    let sag = tip_z(&arm);
    let mut st = arm.initial_state();
    let n = st.q_rad.len();
    st.q_rad[1..n].fill(0.0);
    let mut lowest: f64 = 0.0;
    for _ in 0..20_000 {
        arm.step(&mut st).unwrap();
        lowest = lowest.min(arm.tip_m(&st.q_rad).unwrap().z);
    }
    let z = arm.tip_m(&st.q_rad).unwrap().z;
    println!("static sag {sag:.6} m; released straight: lowest {lowest:.6} m, after 20 s {z:.6} m");
    assert!(lowest < 1.8 * sag, "no overshoot: {lowest} vs {sag}");
    assert!((z / sag - 1.0).abs() < 1e-3, "{z} vs {sag}");
}

#[test]
fn cantilever_bending_frequencies() {
    let ei = tube_ei_n_m2(E, OD, ID);
    let base = (ei / (mu() * L.powi(4))).sqrt() / (2.0 * std::f64::consts::PI);
    let exact = [1.875104_f64.powi(2) * base, 4.694091_f64.powi(2) * base];
    let m = modes(&cantilever(3, 0.0, 0.0)).unwrap();
    // The out-of-plane bending (clamped by the joint) is the link's alone.
    let out: Vec<f64> = m
        .modes
        .iter()
        .filter(|md| md.link_end_m[0].1[1].abs() > 10.0 * md.link_end_m[0].1[0].abs())
        .map(|md| md.natural_hz)
        .collect();
    for md in &m.modes {
        println!(
            "{:8.4} Hz zeta {:.2e} end {:?}",
            md.natural_hz, md.damping_ratio, md.link_end_m
        );
    }
    println!("out of plane {out:?} vs {exact:?}");
    assert!(
        (out[0] / exact[0] - 1.0).abs() < 0.01,
        "{} vs {}",
        out[0],
        exact[0]
    );
    assert!(
        (out[1] / exact[1] - 1.0).abs() < 0.02,
        "{} vs {}",
        out[1],
        exact[1]
    );
}

fn root() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn all_flexible(
    spec: &longreach_arm::ArmSpec,
    ei: f64,
    zeta: f64,
    modes: usize,
) -> Vec<FlexLinkSpec> {
    (1..spec.links.len())
        .map(|l| FlexLinkSpec {
            link: l,
            ei_n_m2: ei,
            damping_ratio: zeta,
            modes,
            mass_per_length_kg_m: Some(0.5 * spec.links[l].inertial.mass_kg / 3.0),
        })
        .collect()
}

#[test]
fn mass_matrix_is_the_inverse_dynamics_and_sags_are_consistent() {
    let spec = load_urdf(robot_path("longreach5/longreach5.urdf")).unwrap();
    let fd = FlexDynamics::new(&spec, &all_flexible(&spec, 1e6, 0.0, 2)).unwrap();
    let nq = fd.ncoords();
    assert_eq!(nq, 5 + 5 * 4);
    let q: Vec<f64> = (0..nq)
        .map(|i| {
            if i < 5 {
                0.3 * (i as f64 + 1.0).sin()
            } else {
                0.01 * (i as f64).cos()
            }
        })
        .collect();
    let mut k = fd.make_kin();
    fd.kinematics(&q, &mut k);
    let mut m = vec![0.0; nq * nq];
    fd.mass_matrix(&mut k, &mut m);
    let mut g0 = vec![0.0; nq];
    let mut fdyn = fd.clone();
    fdyn.set_gravity(Vector3::zeros());
    let zero = vec![0.0; nq];
    // With no gravity, no rates and no bending, rnea(e_c) is column c of M.
    let q_nostiff = q.clone();
    let mut worst: f64 = 0.0;
    for c in 0..nq {
        let mut e = vec![0.0; nq];
        e[c] = 1.0;
        fdyn.kinematics(&q_nostiff, &mut k);
        let mut tau = vec![0.0; nq];
        fdyn.rnea(&mut k, &q_nostiff, &zero, &e, &mut tau);
        let mut tau0 = vec![0.0; nq];
        fdyn.rnea(&mut k, &q_nostiff, &zero, &zero, &mut tau0);
        for r in 0..nq {
            let d = (tau[r] - tau0[r]) - m[r * nq + c];
            worst = worst
                .max(d.abs() / (1.0 + m[r * nq + r].abs().sqrt() * m[c * nq + c].abs().sqrt()));
        }
    }
    println!("M vs inverse dynamics: worst {worst:.2e}");
    assert!(worst < 1e-9, "{worst}");
    // Kinetic energy rate: d/dt (1/2 qd M qd) = qd . (tau - g - K eta) with no gravity
    // and no stiffness: checked through the energy test below; here the gravity part:
    // rnea at rest is the gradient of the potential energy.
    fd.kinematics(&q, &mut k);
    fd.rnea(&mut k, &q, &zero, &zero, &mut g0);
    let pe = |qq: &[f64]| {
        let mut kk = fd.make_kin();
        fd.kinematics(qq, &mut kk);
        fd.potential_energy(&kk) + fd.elastic_energy(qq)
    };
    let mut worst_g: f64 = 0.0;
    for c in 0..nq {
        let h = 1e-6;
        let (mut qp, mut qm) = (q.clone(), q.clone());
        qp[c] += h;
        qm[c] -= h;
        let grad = (pe(&qp) - pe(&qm)) / (2.0 * h);
        worst_g = worst_g.max((grad - g0[c]).abs() / (1.0 + g0[c].abs()));
    }
    println!("gravity + stiffness vs the gradient of the potential: worst {worst_g:.2e}");
    assert!(worst_g < 1e-6, "{worst_g}");
}

fn longreach5_scenario(name: &str) -> DrivenArm {
    scenario::load(&root().join("scenarios").join(name))
        .unwrap()
        .arm
}

#[test]
fn stiff_links_are_the_rigid_arm() {
    let rigid = longreach5_scenario("arm_dyneema2_distal_step.toml");
    let spec = rigid.spec().clone();
    let stiff = rigid
        .clone()
        .with_flexible_links(all_flexible(&spec, 1e13, 0.0, 2))
        .unwrap();
    let (mut a, mut b) = (rigid.initial_state(), stiff.initial_state());
    let mut worst: f64 = 0.0;
    for _ in 0..10_000 {
        rigid.step(&mut a).unwrap();
        stiff.step(&mut b).unwrap();
        for j in 0..5 {
            worst = worst.max((a.q_rad[j] - b.q_rad[j]).abs());
        }
    }
    println!("EI = 1e13 N*m^2 vs rigid over 10 s: joint angles within {worst:.2e} rad");
    assert!(worst < 1e-9, "{worst}");
}

#[test]
fn the_rigid_flag_is_bitwise_the_rigid_arm() {
    let dir = tempfile::tempdir().unwrap();
    let base =
        std::fs::read_to_string(root().join("scenarios/arm_dyneema2_distal_step.toml")).unwrap();
    let base = scenario::with_absolute_paths(&base, &root().join("scenarios"));
    let flagged = format!("{base}\n[[flex]]\nlink = \"*\"\nei_n_m2 = 1e6\nrigid = true\n");
    let a = scenario::parse(&base, "base.toml", dir.path()).unwrap().arm;
    let b = scenario::parse(&flagged, "flagged.toml", dir.path())
        .unwrap()
        .arm;
    assert!(b.flex().is_none());
    let (mut sa, mut sb) = (a.initial_state(), b.initial_state());
    for _ in 0..3000 {
        a.step(&mut sa).unwrap();
        b.step(&mut sb).unwrap();
        assert_eq!(sa.q_rad, sb.q_rad);
        assert_eq!(sa.motor_rad, sb.motor_rad);
    }
}

/// The tubes of longreach5 (robots/longreach5/README.md), E = 110 GPa, 1600 kg/m^3.
fn longreach5_tubes(damping_ratio: f64) -> Vec<FlexLinkSpec> {
    let d = [
        (0.22, 0.21),
        (0.2, 0.191),
        (0.18, 0.172),
        (0.16, 0.153),
        (0.14, 0.134),
    ];
    d.iter()
        .enumerate()
        .map(|(i, &(od, id))| FlexLinkSpec {
            link: i + 1,
            ei_n_m2: tube_ei_n_m2(E, od, id),
            damping_ratio,
            modes: 2,
            mass_per_length_kg_m: Some(RHO * std::f64::consts::PI * (od * od - id * id) / 4.0),
        })
        .collect()
}

#[test]
fn undamped_flexible_arm_keeps_its_energy() {
    // longreach5, every tube flexible and undamped, elastic ropes, motors held, no
    // gravity, no joint damping: kicked joints and bending modes exchange energy with
    // the ropes. (Kicked rates, not displaced modes: the step starts from the state's
    // accelerations, and a displaced mode's would not be zero.)
    let spec = load_urdf(robot_path("longreach5/longreach5.urdf")).unwrap();
    let pairs = uniform_pairs(
        &spec,
        "dyneema2",
        LawKind::Elastic,
        0.1,
        2000.0,
        Tensioner::Fixed,
        kinematic(),
    );
    let arm = DrivenArm::new(spec, pairs, vec![Command::Hold; 5], vec![0.0; 5], 1e-3)
        .unwrap()
        .with_joint_damping(0.0)
        .with_gravity(Vector3::zeros())
        .with_flexible_links(longreach5_tubes(0.0))
        .unwrap();
    let mut st = arm.initial_state();
    st.qd_rad_s[..5].copy_from_slice(&[0.05, -0.04, 0.06, -0.05, 0.08]);
    for c in 5..st.q_rad.len() {
        st.qd_rad_s[c] = 0.1 * ((c as f64) * 0.7).sin();
    }
    let e0 = arm.energy(&st).total_j();
    let (mut worst, mut ke_max, mut el_max): (f64, f64, f64) = (0.0, 0.0, 0.0);
    for _ in 0..10_000 {
        arm.step(&mut st).unwrap();
        let e = arm.energy(&st);
        worst = worst.max((e.total_j() - e0).abs());
        ke_max = ke_max.max(e.links_kinetic_j);
        el_max = el_max.max(e.links_elastic_j);
    }
    println!(
        "energy {e0:.4} J (links kinetic up to {ke_max:.4} J, bending up to {el_max:.4} J): largest change over 10 s {worst:.3e} J = {:.2e} of the total, {:.2e} of the largest kinetic energy",
        worst / e0,
        worst / ke_max
    );
    assert!(el_max > 0.5 && ke_max > 1.0, "nothing exchanged");
    assert!(worst < 1e-4 * e0, "{worst} J of {e0} J");
    assert!(worst < 1e-3 * ke_max, "{worst} J vs kinetic {ke_max} J");
}

#[test]
fn modes_of_the_rig_are_its_transfer_functions_resonance() {
    for (rope, kind) in [
        ("stainless1", LawKind::Elastic),
        ("dyneema2", LawKind::FourElement),
    ] {
        let params = Catalog::builtin().get(rope).unwrap().clone();
        let law = RopeLaw::from_params(&params, kind).unwrap();
        let mean = 490.0;
        let spec = load_urdf(robot_path("rig/rig.urdf")).unwrap();
        let pair = rig_pair(rope, law.clone(), mean, 490.0, Tensioner::ConstantForce);
        let arm = DrivenArm::new(spec, vec![pair], vec![Command::Hold], vec![0.0], 1e-4).unwrap();
        let m = modes(&arm).unwrap();
        let rig = RigSpec::paper(rope, law, 0.05, mean);
        let res = rig_resonance(&rig, 0.5, 20.0).unwrap();
        let md = &m.modes[0];
        // The gain of a second-order pole peaks at f_n sqrt(1 - 2 zeta^2).
        let peak = md.natural_hz * (1.0 - 2.0 * md.damping_ratio.powi(2)).sqrt();
        println!(
            "{rope}: modes {:.4} Hz (zeta {:.4}, peak of its pole at {peak:.4} Hz; {} modes), eq. 12/13 resonance {:.4} Hz, shares {:?}",
            md.natural_hz, md.damping_ratio, m.modes.len(), res.frequency_hz, md.shares
        );
        let tol = if kind == LawKind::Elastic {
            0.002
        } else {
            0.02
        };
        assert!(
            (peak / res.frequency_hz - 1.0).abs() < tol,
            "{rope}: {peak} vs {}",
            res.frequency_hz
        );
    }
}

#[test]
fn modes_of_flexible_longreach5_are_the_peaks_of_its_impulse_response() {
    let arm = longreach5_scenario("flex_dyneema2_base_step.toml")
        .with_commands(vec![Command::Hold; 5])
        .unwrap();
    let m = modes(&arm).unwrap();
    for md in m.modes.iter().take(8) {
        println!(
            "{:8.3} Hz zeta {:.4}: {:?}",
            md.natural_hz,
            md.damping_ratio,
            md.shares
                .iter()
                .take(3)
                .map(|s| format!("{} {:.0}%", s.part, 100.0 * s.share))
                .collect::<Vec<_>>()
        );
    }
    // The response to a kick of every joint and mode, less the unkicked run (the
    // ropes creep under the static load): the linear impulse response.
    let (mut a, mut b) = (arm.initial_state(), arm.initial_state());
    for (c, v) in b.qd_rad_s.iter_mut().enumerate() {
        *v += if c < 5 { 1e-3 } else { 1e-3 * (c as f64).sin() };
    }
    let dt = arm.dt_s();
    let steps = 20_000;
    let nq = a.q_rad.len();
    let mut series = vec![Vec::with_capacity(steps); nq];
    for _ in 0..steps {
        arm.step(&mut a).unwrap();
        arm.step(&mut b).unwrap();
        for c in 0..nq {
            series[c].push(b.q_rad[c] - a.q_rad[c]);
        }
    }
    // Power spectrum, every coordinate normalised by its RMS, on a fine grid.
    let power = |f: f64| -> f64 {
        let w = 2.0 * std::f64::consts::PI * f * dt;
        series
            .iter()
            .map(|s| {
                let rms = (s.iter().map(|x| x * x).sum::<f64>() / s.len() as f64)
                    .sqrt()
                    .max(1e-300);
                let (mut re, mut im) = (0.0, 0.0);
                for (k, x) in s.iter().enumerate() {
                    let (sn, cs) = (w * k as f64).sin_cos();
                    re += x * cs;
                    im -= x * sn;
                }
                (re * re + im * im) / (rms * rms)
            })
            .sum()
    };
    let mut checked = 0;
    // Lightly damped modes make peaks (a heavily damped one, the rope-and-servo modes
    // at zeta 0.1-0.3, is a broad hump the neighbours shift).
    for md in m.modes.iter().filter(|md| md.damping_ratio < 0.05).take(4) {
        let f0 = md.damped_hz;
        let grid: Vec<f64> = (0..=80).map(|i| f0 * (0.96 + 0.001 * i as f64)).collect();
        let p: Vec<f64> = grid.iter().map(|&f| power(f)).collect();
        let (imax, _) = p
            .iter()
            .enumerate()
            .max_by(|x, y| x.1.total_cmp(y.1))
            .unwrap();
        let peak = grid[imax];
        let interior = imax > 0 && imax < grid.len() - 1;
        println!(
            "mode {f0:.4} Hz (damped): spectrum peak {peak:.4} Hz ({:+.2}%), interior {interior}",
            100.0 * (peak / f0 - 1.0)
        );
        assert!(
            interior && (peak / f0 - 1.0).abs() < 0.02,
            "mode {f0} Hz: peak at {peak} Hz"
        );
        checked += 1;
    }
    assert!(checked >= 3, "only {checked} lightly damped modes");
}

#[test]
fn flex_entries_parse_and_name_their_errors() {
    let sc = scenario::load(&root().join("scenarios/flex_dyneema2_base_step.toml")).unwrap();
    let f = sc.arm.flex().expect("flexible");
    assert_eq!(sc.arm.ncoords(), 5 + 5 * 4);
    // The tube's own mass per length (density), the housings on the ends.
    let l1 = &f.flex[0];
    assert!((l1.mass_per_length_kg_m - 14.049202346854 / 2.6).abs() < 1e-6);
    assert!((l1.ei_n_m2 - tube_ei_n_m2(E, 0.22, 0.21)).abs() < 1e-3);
    let base =
        std::fs::read_to_string(root().join("scenarios/arm_dyneema2_base_step.toml")).unwrap();
    let base = scenario::with_absolute_paths(&base, &root().join("scenarios"));
    let dir = tempfile::tempdir().unwrap();
    let parse = |extra: &str| scenario::parse(&format!("{base}\n{extra}"), "f.toml", dir.path());
    // The registry's link effect scales EI and sets the damping.
    let a = parse("[[flex]]\nlink = \"link2\"\nei_n_m2 = 1e6\neffects = [{ name = \"link_flexibility\", params = [2.0, 0.05] }]\n").unwrap();
    let l = &a.arm.flex().unwrap().flex[0];
    assert!((l.ei_n_m2 - 2e6).abs() < 1e-6 && l.link == 2);
    for (extra, field) in [
        ("[[flex]]\nlink = \"nope\"\nei_n_m2 = 1e6\n", "flex.0.link"),
        ("[[flex]]\nlink = \"link1\"\n", "flex.0"),
        ("[[flex]]\nlink = \"link1\"\nei_n_m2 = 1e6\nmodes = 7\n", "flex.0.modes"),
        ("[[flex]]\nlink = \"link1\"\nei_n_m2 = 1e6\nmass_per_length_kg_m = 100.0\n", "flex.0"),
        ("[[flex]]\nlink = \"link1\"\nei_n_m2 = 1e6\neffects = [{ name = \"joint_friction\" }]\n", "flex.0.effects.0"),
    ] {
        let e = parse(extra).unwrap_err();
        println!("{e}");
        assert_eq!(e.field, field, "{extra}: {e}");
        assert!(e.line.is_some() && !e.fix.is_empty(), "{e}");
    }
    // A beam lighter than its link but heavier along it than the link is: link5's
    // 3.72 kg tube carries a 5 kg payload at its end; a 0.16 m tube (4.95 kg over its
    // 1.8 m) leaves the other 3.77 kg at 2.09 m, past the link's end, which only a
    // negative moment of inertia about that point could give (it once went NaN at the
    // first step).
    let e = parse(
        "[[flex]]\nlink = \"link5\"\nyoungs_modulus_pa = 110e9\nouter_diameter_m = 0.16\n\
         inner_diameter_m = 0.153\ndensity_kg_m3 = 1600.0\n",
    )
    .unwrap_err();
    assert_eq!(e.field, "flex.0", "{e}");
    assert!(e.to_string().contains("negative moment of inertia"), "{e}");
    // The shipped tube on it (3.718 kg, the URDF's) is one.
    parse(
        "[[flex]]\nlink = \"link5\"\nyoungs_modulus_pa = 110e9\nouter_diameter_m = 0.14\n\
         inner_diameter_m = 0.134\ndensity_kg_m3 = 1600.0\n",
    )
    .unwrap();
}
