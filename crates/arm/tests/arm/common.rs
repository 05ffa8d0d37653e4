//! Shared helpers for the integration tests.

use std::path::PathBuf;

/// Path of a file under the workspace `robots/` folder.
pub fn robot_path(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../robots")
        .join(rel)
}

/// A 3D test arm exercising every frame feature: joint origins with rpy, tilted and
/// negative axes, rotated inertial frames, off-axis centres of mass, a fixed child with
/// mass (merged), and a tip frame.
pub const TWISTED_URDF: &str = r#"<?xml version="1.0"?>
<robot name="twisted">
  <link name="base"/>
  <link name="a">
    <inertial>
      <origin xyz="0.1 0.05 0.3" rpy="0.2 -0.1 0.4"/>
      <mass value="3.0"/>
      <inertia ixx="0.05" ixy="0.004" ixz="-0.002" iyy="0.04" iyz="0.003" izz="0.03"/>
    </inertial>
  </link>
  <link name="b">
    <inertial>
      <origin xyz="0.4 -0.02 0.01" rpy="-0.3 0.5 0.1"/>
      <mass value="2.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.08" iyz="0" izz="0.085"/>
    </inertial>
  </link>
  <link name="b_weight">
    <inertial>
      <origin xyz="0.02 0.03 0" rpy="0 0 0.7"/>
      <mass value="0.7"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.004"/>
    </inertial>
  </link>
  <link name="c">
    <inertial>
      <origin xyz="0.25 0.03 -0.04" rpy="0.9 0.2 -0.6"/>
      <mass value="1.2"/>
      <inertia ixx="0.004" ixy="0.0005" ixz="0" iyy="0.02" iyz="0" izz="0.021"/>
    </inertial>
  </link>
  <link name="tip"/>
  <joint name="yaw" type="continuous">
    <parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.2" rpy="0 0 0.3"/>
    <axis xyz="0 0 1"/>
  </joint>
  <joint name="pitch" type="revolute">
    <parent link="a"/><child link="b"/>
    <origin xyz="0.05 0 0.5" rpy="0.4 -0.2 0.1"/>
    <axis xyz="0 -1 0"/>
    <limit lower="-3" upper="3" effort="100" velocity="2"/>
  </joint>
  <joint name="weight_fixed" type="fixed">
    <parent link="b"/><child link="b_weight"/>
    <origin xyz="0.6 0.05 -0.02" rpy="0.3 0.2 0.1"/>
  </joint>
  <joint name="tilt" type="continuous">
    <parent link="b"/><child link="c"/>
    <origin xyz="0.7 0 0" rpy="0 0.3 -0.5"/>
    <axis xyz="0.3 0.8 -0.2"/>
  </joint>
  <joint name="tip_fixed" type="fixed">
    <parent link="c"/><child link="tip"/>
    <origin xyz="0.5 0 0"/>
  </joint>
</robot>
"#;

use longreach_arm::{
    load_urdf, ArmSpec, Command, DrivenArm, MotorMode, MotorSpec, PairSpec, Tensioner,
};
use longreach_rope::{Catalog, LawKind, RopeLaw};

/// One rope pair per joint of `spec`, every pulley of radius `r_m`, relays at every
/// proximal joint, catalog rope `rope` with law `kind`.
pub fn uniform_pairs(
    spec: &ArmSpec,
    rope: &str,
    kind: LawKind,
    r_m: f64,
    preload_n: f64,
    tensioner: Tensioner,
    motor: MotorSpec,
) -> Vec<PairSpec> {
    let params = Catalog::builtin().get(rope).unwrap().clone();
    let law = RopeLaw::from_params(&params, kind).unwrap();
    longreach_arm::transmission::uniform_pairs(
        spec, rope, &params, &law, r_m, preload_n, tensioner, motor, 0.5,
    )
}

/// A servo motor with the given gains.
pub fn servo(inertia: f64, kp: f64, kd: f64) -> MotorSpec {
    MotorSpec {
        inertia_kg_m2: inertia,
        damping_n_m_s: 0.0,
        mode: MotorMode::Servo {
            kp_n_m_per_rad: kp,
            kd_n_m_s_per_rad: kd,
            torque_limit_n_m: f64::INFINITY,
            gravity_feedforward: true,
        },
        friction: None,
    }
}

/// A trapezoidal move to `to_rad` from `start_s` at `max_velocity_rad_s`,
/// `max_accel_rad_s2`.
pub fn trapezoid(
    to_rad: f64,
    start_s: f64,
    max_velocity_rad_s: f64,
    max_accel_rad_s2: f64,
) -> Command {
    Command::Trapezoid {
        to_rad,
        start_s,
        max_velocity_rad_s,
        max_accel_rad_s2,
    }
}

/// A kinematic motor (its angle is the reference).
pub fn kinematic() -> MotorSpec {
    MotorSpec {
        inertia_kg_m2: 0.0,
        damping_n_m_s: 0.0,
        mode: MotorMode::Kinematic,
        friction: None,
    }
}

/// arm5 (the MuJoCo anchor) with elastic stainless ropes, r = 25 mm, servo motors.
pub fn arm5_driven(motor: MotorSpec, commands: Vec<Command>) -> DrivenArm {
    arm5_driven_preload(motor, commands, 20000.0)
}

/// [`arm5_driven`] with another preload per rope, N.
pub fn arm5_driven_preload(motor: MotorSpec, commands: Vec<Command>, preload_n: f64) -> DrivenArm {
    let spec = load_urdf(robot_path("arm5/arm5.urdf")).unwrap();
    let pairs = uniform_pairs(
        &spec,
        "stainless1",
        LawKind::Elastic,
        0.025,
        preload_n,
        Tensioner::Fixed,
        motor,
    );
    DrivenArm::new(spec, pairs, commands, vec![0.0; 5], 1e-3).unwrap()
}

/// The paper's rig's rope pair for robots/rig/rig.urdf through the arm path: one rope
/// per side of `law` between the kinematic motor (r1 = 25 mm) and the output pulley
/// (r2 = 25 mm), L = 15.2 m, no relays.
pub fn rig_pair(
    rope: &str,
    law: RopeLaw,
    preload_n: f64,
    prestretch_n: f64,
    tensioner: Tensioner,
) -> PairSpec {
    PairSpec {
        joint: 0,
        rope_name: rope.into(),
        rope: Catalog::builtin().get(rope).unwrap().clone(),
        law,
        ropes_in_parallel: 1,
        joint_radius_m: 0.025,
        motor_radius_m: 0.025,
        route: vec![],
        length_m: 15.2,
        span_lengths_m: vec![15.2],
        preload_n,
        prestretch_n,
        tensioner,
        motor: kinematic(),
        effects: vec![],
        relay_friction: None,
    }
}
