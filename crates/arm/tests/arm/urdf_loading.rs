//! URDF loading: the shipped robots, fixed-joint merging, errors and warnings.

use crate::common;

use longreach_arm::dynamics::{mass_matrix, tip_position_m};
use longreach_arm::{chain_urdf, gravity_torques, load_urdf, parse_urdf, ArmSpec, UrdfError};
use nalgebra::{Matrix3, Vector3};
use std::path::PathBuf;

fn write_temp(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, text).expect("write temp urdf");
    path
}

/// Loads `text` from a file named `name` and returns the error message.
fn load_error(name: &str, text: &str) -> (String, UrdfError) {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write_temp(&dir, name, text);
    let err = load_urdf(&path).expect_err("this URDF must be rejected");
    let msg = err.to_string();
    assert!(
        msg.contains(&path.display().to_string()),
        "message does not name the file: {msg}"
    );
    (msg, err)
}

const LINK_OK: &str = r#"<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>"#;

fn robot(body: &str) -> String {
    format!("<?xml version=\"1.0\"?>\n<robot name=\"t\">\n{body}\n</robot>\n")
}

// --------------------------------------------------------------------------------
// The shipped robots.

#[test]
fn arm5_matches_the_mujoco_anchor_and_the_generator() {
    let spec = load_urdf(common::robot_path("arm5/arm5.urdf")).unwrap();
    assert!(spec.warnings.is_empty(), "{:?}", spec.warnings);
    assert_eq!(spec.ndofs(), 5);
    for (j, joint) in spec.joints.iter().enumerate() {
        assert_eq!(joint.name, format!("q{}", j + 1));
        assert!((joint.damping_n_m_s_per_rad - 0.01).abs() < 1e-15);
        assert!(joint.limits_rad.is_none());
        assert!((joint.axis.into_inner() - Vector3::y()).norm() < 1e-15);
        let x = if j == 0 { 0.0 } else { 2.0 };
        assert!(
            (joint.parent_from_joint.translation.vector - Vector3::new(x, 0.0, 0.0)).norm() < 1e-15
        );
    }
    // MuJoCo: inertial pos="1.0 0 0" mass="10.0" diaginertia="0.05333 3.3599983 3.3599983".
    for link in &spec.links[1..] {
        let i = &link.inertial;
        assert!((i.mass_kg - 10.0).abs() < 1e-15);
        assert!((i.com_m - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-15);
        let d = Matrix3::from_diagonal(&Vector3::new(0.05333, 3.3599983, 3.3599983));
        assert!((i.inertia_kg_m2 - d).abs().max() < 1e-15);
    }
    // MuJoCo site "tip" at pos="2.0 0 0" on link5: reach 10 m.
    let tip = tip_position_m(&spec, &[0.0; 5]).unwrap();
    assert!((tip - Vector3::new(10.0, 0.0, 0.0)).norm() < 1e-12);
    // Same arm as the generator, to the digits MuJoCo prints.
    let generated = parse_urdf(&chain_urdf(5, 2.0, 10.0), "chain5").unwrap();
    for (a, b) in spec.links.iter().zip(&generated.links) {
        let rel = (a.inertial.inertia_kg_m2 - b.inertial.inertia_kg_m2)
            .abs()
            .max()
            / 3.36;
        assert!(rel < 1e-8, "{rel}");
    }
    assert_eq!(spec.joints, generated.joints);
}

#[test]
fn rig_has_the_paper_inertia_and_no_gravity_torque() {
    let spec = load_urdf(common::robot_path("rig/rig.urdf")).unwrap();
    assert!(spec.warnings.is_empty(), "{:?}", spec.warnings);
    assert_eq!(spec.ndofs(), 1);
    let joint = &spec.joints[0];
    assert!((joint.damping_n_m_s_per_rad - 0.05).abs() < 1e-15);
    // Inertia about the joint axis: paper I = 2.84e4 kg*mm^2.
    let m = mass_matrix(&spec, &[0.3]).unwrap();
    assert!((m[(0, 0)] - 0.0284).abs() < 1e-15, "{}", m[(0, 0)]);
    for q in [0.0, 0.7, -2.0, 3.0] {
        let g = gravity_torques(&spec, &[q]).unwrap();
        assert!(g[0].abs() < 1e-12, "gravity torque {} at q = {q}", g[0]);
    }
    // Rope leaves the rim at r2 = 25 mm.
    let rim = tip_position_m(&spec, &[0.0]).unwrap();
    assert!((rim.norm() - 0.025).abs() < 1e-15);
    assert!(spec
        .links[1]
        .visuals
        .iter()
        .any(|v| matches!(v.geometry, longreach_arm::spec::Geometry::Cylinder { radius_m, .. } if (radius_m - 0.025).abs() < 1e-15)));
}

/// The longreach5 design numbers (README) against hand sums from the design
/// parameters (tube formula, lumped housings and payload).
#[test]
fn longreach5_design_numbers() {
    let spec = load_urdf(common::robot_path("longreach5/longreach5.urdf")).unwrap();
    assert!(spec.warnings.is_empty(), "{:?}", spec.warnings);
    assert_eq!(spec.ndofs(), 5);
    let rho = 1600.0;
    let tubes = [
        (2.6, 0.220, 0.005),
        (2.4, 0.200, 0.0045),
        (2.2, 0.180, 0.004),
        (2.0, 0.160, 0.0035),
        (1.8, 0.140, 0.003),
    ];
    let housings = [5.0, 4.0, 3.0, 2.0];
    let payload = 5.0;
    // Point masses along x at q = 0: (mass, x).
    let mut masses: Vec<(f64, f64)> = Vec::new();
    let mut start = 0.0;
    for (k, &(l, od, wall)) in tubes.iter().enumerate() {
        let ro: f64 = od / 2.0;
        let ri = ro - wall;
        let m = rho * std::f64::consts::PI * (ro * ro - ri * ri) * l;
        let mut link_mass = m;
        masses.push((m, start + l / 2.0));
        if k < 4 {
            masses.push((housings[k], start + l));
            link_mass += housings[k];
        } else {
            masses.push((payload, start + l));
            link_mass += payload;
        }
        assert!(
            (spec.links[k + 1].inertial.mass_kg - link_mass).abs() < 1e-9,
            "link {} mass {}",
            k + 1,
            spec.links[k + 1].inertial.mass_kg
        );
        start += l;
    }
    assert!((start - 11.0).abs() < 1e-12);
    let tip = tip_position_m(&spec, &[0.0; 5]).unwrap();
    assert!((tip - Vector3::new(11.0, 0.0, 0.0)).norm() < 1e-12);
    let total: f64 = masses.iter().map(|m| m.0).sum();
    assert!((spec.moving_mass_kg() - total).abs() < 1e-9);
    // Horizontal pose: tau_j = -g * sum over masses beyond joint j of m (x - x_j).
    let g = gravity_torques(&spec, &[0.0; 5]).unwrap();
    let joint_x = [0.0, 2.6, 5.0, 7.2, 9.2];
    for j in 0..5 {
        let expected: f64 = -9.81
            * masses
                .iter()
                .filter(|(_, x)| *x > joint_x[j])
                .map(|(m, x)| m * (x - joint_x[j]))
                .sum::<f64>();
        assert!(
            (g[j] - expected).abs() < 1e-9 * expected.abs(),
            "joint {}: {} vs {expected}",
            j + 1,
            g[j]
        );
    }
    // README table.
    let readme = [-3107.76, -1739.41, -884.37, -385.44, -121.12];
    for j in 0..5 {
        assert!(
            (g[j] - readme[j]).abs() < 0.006,
            "README j{}: {}",
            j + 1,
            g[j]
        );
    }
}

// --------------------------------------------------------------------------------
// Fixed-joint merging.

/// Parent P (2 kg) with a fixed child C (1 kg, turned 90 deg about z, rotated
/// inertia), and a revolute joint hanging off C. The hand-merged file has the combined
/// inertial (computed by hand with exact fractions) and the joint origin composed by
/// hand.
const WITH_FIXED: &str = r#"<robot name="m">
  <link name="base"/>
  <link name="P">
    <inertial><origin xyz="0.5 0 0"/><mass value="2"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.2"/></inertial>
  </link>
  <link name="C">
    <inertial><origin xyz="0.2 0 0"/><mass value="1"/>
      <inertia ixx="0.03" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.03"/></inertial>
  </link>
  <link name="D">
    <inertial><origin xyz="0.3 0 0"/><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="j1" type="continuous">
    <parent link="base"/><child link="P"/><axis xyz="0 1 0"/>
  </joint>
  <joint name="fix" type="fixed">
    <parent link="P"/><child link="C"/>
    <origin xyz="1 0 0" rpy="0 0 1.5707963267948966"/>
  </joint>
  <joint name="j2" type="continuous">
    <parent link="C"/><child link="D"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 1 0"/>
  </joint>
</robot>"#;

const HAND_MERGED: &str = r#"<robot name="m">
  <link name="base"/>
  <link name="P">
    <inertial><origin xyz="0.6666666666666666 0.06666666666666667 0"/><mass value="3"/>
      <inertia ixx="0.03766666666666667" ixy="-0.06666666666666667" ixz="0"
               iyy="0.39666666666666667" iyz="0" izz="0.42333333333333334"/></inertial>
  </link>
  <link name="D">
    <inertial><origin xyz="0.3 0 0"/><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="j1" type="continuous">
    <parent link="base"/><child link="P"/><axis xyz="0 1 0"/>
  </joint>
  <joint name="j2" type="continuous">
    <parent link="P"/><child link="D"/>
    <origin xyz="1 0.5 0" rpy="0 0 1.5707963267948966"/><axis xyz="0 1 0"/>
  </joint>
</robot>"#;

#[test]
fn fixed_joint_merging_equals_hand_merged() {
    let merged = parse_urdf(WITH_FIXED, "with_fixed").unwrap();
    let hand = parse_urdf(HAND_MERGED, "hand").unwrap();
    assert_eq!(merged.links.len(), 3);
    assert_eq!(merged.links[1].merged_links, vec!["C".to_string()]);
    let (a, b) = (&merged.links[1].inertial, &hand.links[1].inertial);
    assert!((a.mass_kg - b.mass_kg).abs() < 1e-15);
    assert!(
        (a.com_m - b.com_m).norm() < 1e-15,
        "{} vs {}",
        a.com_m,
        b.com_m
    );
    assert!(
        (a.inertia_kg_m2 - b.inertia_kg_m2).abs().max() < 1e-15,
        "{} vs {}",
        a.inertia_kg_m2,
        b.inertia_kg_m2
    );
    let (ja, jb) = (&merged.joints[1], &hand.joints[1]);
    assert_eq!(ja.parent_link, jb.parent_link);
    assert!(
        (ja.parent_from_joint.translation.vector - jb.parent_from_joint.translation.vector).norm()
            < 1e-15
    );
    assert!(
        ja.parent_from_joint
            .rotation
            .angle_to(&jb.parent_from_joint.rotation)
            < 1e-15
    );
    // Same dynamics.
    for q in [[0.3, -0.4], [1.2, 2.0]] {
        let ga = gravity_torques(&merged, &q).unwrap();
        let gb = gravity_torques(&hand, &q).unwrap();
        for j in 0..2 {
            assert!((ga[j] - gb[j]).abs() < 1e-12);
        }
    }
    // The merged link stays available as a frame.
    let c = merged.frame("C").unwrap();
    assert_eq!(c.link, 1);
    assert!((c.link_from_frame.translation.vector - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-15);
}

#[test]
fn massless_fixed_chain_to_the_world_is_merged_into_the_base() {
    let text = robot(&format!(
        r#"<link name="world"/><link name="base_link"/><link name="a">{LINK_OK}</link>
        <joint name="anchor" type="fixed"><parent link="world"/><child link="base_link"/>
          <origin xyz="0 0 1"/></joint>
        <joint name="j" type="continuous"><parent link="base_link"/><child link="a"/>
          <axis xyz="0 0 1"/></joint>"#
    ));
    let spec = parse_urdf(&text, "world").unwrap();
    assert_eq!(spec.links[0].name, "world");
    assert_eq!(spec.links[0].merged_links, vec!["base_link".to_string()]);
    assert!((spec.joints[0].parent_from_joint.translation.vector.z - 1.0).abs() < 1e-15);
}

// --------------------------------------------------------------------------------
// Errors.

#[test]
fn error_cycle_names_the_joints() {
    let text = robot(&format!(
        r#"<link name="r"/><link name="a">{LINK_OK}</link><link name="b">{LINK_OK}</link>
        <link name="c">{LINK_OK}</link>
        <joint name="ab" type="continuous"><parent link="a"/><child link="b"/></joint>
        <joint name="bc" type="continuous"><parent link="b"/><child link="c"/></joint>
        <joint name="ca" type="continuous"><parent link="c"/><child link="a"/></joint>"#
    ));
    let (msg, _) = load_error("cycle.urdf", &text);
    assert!(msg.contains("cycle") || msg.contains("loop"), "{msg}");
    for j in ["ab", "bc", "ca"] {
        assert!(msg.contains(j), "{msg}");
    }
}

#[test]
fn error_two_parents_names_the_link() {
    let text = robot(&format!(
        r#"<link name="r"/><link name="a">{LINK_OK}</link><link name="b">{LINK_OK}</link>
        <joint name="ra" type="continuous"><parent link="r"/><child link="a"/></joint>
        <joint name="rb" type="continuous"><parent link="r"/><child link="b"/></joint>
        <joint name="ab" type="continuous"><parent link="a"/><child link="b"/></joint>"#
    ));
    let (msg, _) = load_error("two_parents.urdf", &text);
    assert!(
        msg.contains("link 'b'") && msg.contains("'rb'") && msg.contains("'ab'"),
        "{msg}"
    );
}

#[test]
fn error_missing_link_names_joint_and_link() {
    let text = robot(&format!(
        r#"<link name="r"/><link name="a">{LINK_OK}</link>
        <joint name="ra" type="continuous"><parent link="r"/><child link="a"/></joint>
        <joint name="a_ghost" type="continuous"><parent link="a"/><child link="ghost"/></joint>"#
    ));
    let (msg, err) = load_error("missing.urdf", &text);
    assert!(
        msg.contains("joint 'a_ghost'") && msg.contains("'ghost'"),
        "{msg}"
    );
    // The line of the joint element (line 1 is the XML declaration).
    assert!(
        matches!(err, UrdfError::Invalid { line: Some(5), .. }),
        "{err:?}"
    );
}

#[test]
fn error_negative_mass_names_the_link() {
    let text = robot(
        r#"<link name="r"/>
        <link name="heavy"><inertial><mass value="-1"/>
          <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
        <joint name="j" type="continuous"><parent link="r"/><child link="heavy"/></joint>"#,
    );
    let (msg, _) = load_error("negative_mass.urdf", &text);
    assert!(msg.contains("link 'heavy'") && msg.contains("-1"), "{msg}");
}

#[test]
fn error_zero_mass_moving_link_names_the_link() {
    let text = robot(
        r#"<link name="r"/><link name="ghost_link"/>
        <joint name="j" type="continuous"><parent link="r"/><child link="ghost_link"/></joint>"#,
    );
    let (msg, _) = load_error("zero_mass.urdf", &text);
    assert!(
        msg.contains("link 'ghost_link'") && msg.contains("mass 0 kg"),
        "{msg}"
    );
}

#[test]
fn error_non_positive_definite_inertia_names_the_link() {
    let text = robot(
        r#"<link name="r"/>
        <link name="flat"><inertial><mass value="1"/>
          <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0"/></inertial></link>
        <joint name="j" type="continuous"><parent link="r"/><child link="flat"/></joint>"#,
    );
    let (msg, _) = load_error("flat.urdf", &text);
    assert!(
        msg.contains("link 'flat'") && msg.contains("positive definite"),
        "{msg}"
    );
    let text = robot(
        r#"<link name="r"/>
        <link name="neg"><inertial><mass value="1"/>
          <inertia ixx="0.01" ixy="0.05" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
        <joint name="j" type="continuous"><parent link="r"/><child link="neg"/></joint>"#,
    );
    let (msg, _) = load_error("neg_inertia.urdf", &text);
    assert!(
        msg.contains("link 'neg'") && msg.contains("negative principal moment"),
        "{msg}"
    );
}

#[test]
fn error_zero_axis_names_the_joint() {
    let text = robot(&format!(
        r#"<link name="r"/><link name="a">{LINK_OK}</link>
        <joint name="spin" type="continuous"><parent link="r"/><child link="a"/>
          <axis xyz="0 0 0"/></joint>"#
    ));
    let (msg, _) = load_error("zero_axis.urdf", &text);
    assert!(
        msg.contains("joint 'spin'") && msg.contains("axis"),
        "{msg}"
    );
}

#[test]
fn error_bad_xml_gives_file_and_line() {
    let text = "<robot name=\"t\">\n  <link name=\"a\">\n  </lnk>\n</robot>\n";
    let (msg, err) = load_error("bad.urdf", text);
    assert!(msg.contains("malformed XML"), "{msg}");
    assert!(matches!(err, UrdfError::Xml { line: 3, .. }), "{err:?}");
    let (msg, _) = load_error("unclosed.urdf", "<robot name=\"t\">\n  <link name=\"a\">\n");
    assert!(msg.contains("malformed XML"), "{msg}");
}

#[test]
fn error_prismatic_and_reversed_limits() {
    let text = robot(&format!(
        r#"<link name="r"/><link name="a">{LINK_OK}</link>
        <joint name="slide" type="prismatic"><parent link="r"/><child link="a"/>
          <limit lower="0" upper="1" effort="1" velocity="1"/></joint>"#
    ));
    let (msg, _) = load_error("prismatic.urdf", &text);
    assert!(
        msg.contains("joint 'slide'") && msg.contains("Prismatic"),
        "{msg}"
    );
    let text = robot(&format!(
        r#"<link name="r"/><link name="a">{LINK_OK}</link>
        <joint name="backwards" type="revolute"><parent link="r"/><child link="a"/>
          <limit lower="1" upper="-1" effort="1" velocity="1"/></joint>"#
    ));
    let (msg, _) = load_error("limits.urdf", &text);
    assert!(
        msg.contains("joint 'backwards'") && msg.contains("lower"),
        "{msg}"
    );
}

#[test]
fn error_missing_file() {
    let err = load_urdf("/nonexistent/dir/arm.urdf").unwrap_err();
    assert!(
        err.to_string().contains("/nonexistent/dir/arm.urdf"),
        "{err}"
    );
}

// --------------------------------------------------------------------------------
// Warnings.

#[test]
fn warnings_name_everything_not_simulated() {
    let text = robot(&format!(
        r#"<link name="world"/>
        <link name="a">{LINK_OK}
          <collision><geometry><box size="1 1 1"/></geometry></collision>
          <sensor_thing/>
        </link>
        <link name="b">{LINK_OK}</link>
        <joint name="float_base" type="floating"><parent link="world"/><child link="a"/></joint>
        <joint name="follower" type="continuous"><parent link="a"/><child link="b"/>
          <axis xyz="0 0 2"/>
          <mimic joint="float_base"/>
          <safety_controller soft_lower_limit="0" soft_upper_limit="1" k_velocity="1"/>
        </joint>
        <transmission name="trans_follower"><type>SimpleTransmission</type></transmission>
        <gazebo reference="a"><material>Gazebo/Red</material></gazebo>
        <plugin_xyz/>"#
    ));
    let spec = parse_urdf(&text, "warn.urdf").unwrap();
    let all = spec.warnings.join("\n");
    for needle in [
        "transmission",
        "trans_follower",
        "gazebo",
        "reference=\"a\"",
        "collision",
        "link 'a'",
        "sensor_thing",
        "mimic",
        "follower",
        "safety_controller",
        "float_base",
        "treated as fixed",
        "plugin_xyz",
        "axis length 2",
    ] {
        assert!(all.contains(needle), "warnings lack '{needle}':\n{all}");
    }
    // The floating root joint became the fixed base: one moving joint.
    assert_eq!(spec.ndofs(), 1);
    assert_eq!(spec.links[0].merged_links, vec!["a".to_string()]);
}

#[test]
fn revolute_without_limit_is_warned_and_unlimited() {
    let text = robot(&format!(
        r#"<link name="r"/><link name="a">{LINK_OK}</link>
        <joint name="free_rev" type="revolute"><parent link="r"/><child link="a"/></joint>"#
    ));
    let spec = parse_urdf(&text, "nolimit").unwrap();
    assert!(spec.joints[0].limits_rad.is_none());
    assert!(spec
        .warnings
        .iter()
        .any(|w| w.contains("free_rev") && w.contains("<limit>")));
}

#[test]
fn tree_is_accepted_with_parents_first() {
    let text = robot(&format!(
        r#"<link name="r"/><link name="a">{LINK_OK}</link><link name="b">{LINK_OK}</link>
        <link name="c">{LINK_OK}</link>
        <joint name="ab" type="continuous"><parent link="a"/><child link="b"/></joint>
        <joint name="ra" type="continuous"><parent link="r"/><child link="a"/></joint>
        <joint name="ac" type="continuous"><parent link="a"/><child link="c"/></joint>"#
    ));
    let spec: ArmSpec = parse_urdf(&text, "tree").unwrap();
    let names: Vec<&str> = spec.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["ra", "ab", "ac"]);
    assert_eq!(spec.joints[2].parent_link, 1);
}
