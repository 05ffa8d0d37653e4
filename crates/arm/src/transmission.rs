//! Rope transmissions of an arm from its geometry: one antagonistic rope pair per
//! driven joint, routed from a motor pulley at the base over relay pulleys at the
//! proximal joints. The pair itself (routing matrix, spans, relays, tensioner, motor)
//! is the transmission core's ([`longreach_drive::transmission`], re-exported here);
//! this module derives routes and span lengths from the URDF chain.

use longreach_rope::{RopeLaw, RopeParams};

pub use longreach_drive::transmission::{
    CompiledPair, MotorMode, MotorSpec, PairSpec, Relay, RoutingMatrix, Tensioner,
};

/// Joints between the base and `joint` (exclusive), base first.
pub fn proximal_joints(spec: &crate::ArmSpec, joint: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut link = spec.joints[joint].parent_link;
    while link > 0 {
        out.push(link - 1);
        link = spec.joints[link - 1].parent_link;
    }
    out.reverse();
    out
}

/// The default route of the pair driving `joint`: a relay at every proximal joint `k`
/// with radius `joint_radii_m[k]` (the pulley radius of that joint) and sign +1.
pub fn default_route(spec: &crate::ArmSpec, joint: usize, joint_radii_m: &[f64]) -> Vec<Relay> {
    proximal_joints(spec, joint)
        .into_iter()
        .map(|k| Relay {
            joint: Some(k),
            radius_m: joint_radii_m[k],
            sign: 1.0,
        })
        .collect()
}

/// Lengths along the chain of the rope driving `joint`, from the URDF geometry: the
/// motor pulley to the first joint (`motor_offset_m`), then joint origin to joint
/// origin up to the driven joint, m.
pub fn chain_lengths_m(spec: &crate::ArmSpec, joint: usize, motor_offset_m: f64) -> Vec<f64> {
    let mut spans = vec![motor_offset_m];
    let chain: Vec<usize> = proximal_joints(spec, joint)
        .into_iter()
        .chain(std::iter::once(joint))
        .collect();
    for w in chain.windows(2) {
        spans.push(
            spec.joints[w[1]]
                .parent_from_joint
                .translation
                .vector
                .norm(),
        );
    }
    spans
}

/// Span lengths of the rope driving `joint` cut at the relays of `route` (the spans
/// [`PairSpec::span_lengths_m`] holds): the chain lengths of [`chain_lengths_m`]
/// summed between successive relay joints and scaled to `length_m`. Equal spans when
/// the route does not follow the chain (a relay at a joint off the chain, or one fixed
/// to the base) or a span would have zero length.
pub fn relay_span_lengths_m(
    spec: &crate::ArmSpec,
    joint: usize,
    chain_m: &[f64],
    route: &[Relay],
    length_m: f64,
) -> Vec<f64> {
    let mut relay_joints: Vec<Option<usize>> = route.iter().map(|r| r.joint).collect();
    relay_joints.sort_unstable();
    let m = relay_joints.len();
    let equal = vec![length_m / (m + 1) as f64; m + 1];
    let chain: Vec<usize> = proximal_joints(spec, joint)
        .into_iter()
        .chain(std::iter::once(joint))
        .collect();
    if chain_m.len() != chain.len() {
        return equal;
    }
    // Distance of each chain joint from the motor pulley along the rope.
    let mut pos = Vec::with_capacity(chain.len());
    let mut acc = 0.0;
    for s in chain_m {
        acc += s;
        pos.push(acc);
    }
    let at = |j: usize| chain.iter().position(|&c| c == j).map(|i| pos[i]);
    let mut cuts = Vec::with_capacity(m + 2);
    cuts.push(0.0);
    for j in relay_joints {
        match j.and_then(at) {
            Some(p) => cuts.push(p),
            None => return equal,
        }
    }
    cuts.push(acc);
    let spans: Vec<f64> = cuts.windows(2).map(|w| w[1] - w[0]).collect();
    if acc <= 0.0 || spans.iter().any(|s| !(s.is_finite() && *s > 1e-9 * acc)) {
        return equal;
    }
    let scale = length_m / acc;
    spans.iter().map(|s| s * scale).collect()
}

/// One rope pair per joint of `spec`: every pulley (joint, motor, relays) of radius
/// `radius_m`, relays at every proximal joint (sign +1), span lengths from the
/// geometry with the motor `motor_offset_m` before the first joint. For benchmarks,
/// tests and quick studies.
pub fn uniform_pairs(
    spec: &crate::ArmSpec,
    rope_name: &str,
    rope: &RopeParams,
    law: &RopeLaw,
    radius_m: f64,
    preload_n: f64,
    tensioner: Tensioner,
    motor: MotorSpec,
    motor_offset_m: f64,
) -> Vec<PairSpec> {
    let radii = vec![radius_m; spec.ndofs()];
    (0..spec.ndofs())
        .map(|j| {
            let chain = chain_lengths_m(spec, j, motor_offset_m);
            let length_m = chain.iter().sum();
            let route = default_route(spec, j, &radii);
            PairSpec {
                joint: j,
                rope_name: rope_name.to_string(),
                rope: rope.clone(),
                law: law.clone(),
                ropes_in_parallel: 1,
                joint_radius_m: radius_m,
                motor_radius_m: radius_m,
                span_lengths_m: relay_span_lengths_m(spec, j, &chain, &route, length_m),
                route,
                length_m,
                preload_n,
                prestretch_n: 0.0,
                tensioner,
                motor,
                effects: vec![],
                relay_friction: None,
            }
        })
        .collect()
}
