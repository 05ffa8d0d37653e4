//! A payload the model does not know, or knows wrong: an extra point mass where the arm
//! carries its payload.

use super::{check, Args, DataKind, Effect, EffectParam, Payload, Site};
use crate::DriveError;

/// `payload_mass_kg` added to the arm's payload ([`Payload`]): the whole payload when
/// the scenario has none, the error of the scenario's otherwise (negative: lighter).
#[derive(Debug)]
pub struct PayloadMass;

const PARAMS: &[EffectParam] = &[EffectParam {
    name: "payload_mass_kg",
    unit: "kg",
    default: 1.0,
    // Negative: the payload is lighter than the scenario's (the total stays >= 0,
    // checked when the arm is built).
    lower: -1e3,
    upper: 1e3,
    log_scale: false,
    fitted: true,
}];

impl Effect for PayloadMass {
    fn name(&self) -> &'static str {
        "payload_mass"
    }
    fn doc(&self) -> &'static str {
        "The arm carries a payload the model and its controller do not know, or know \
         wrong: a point mass payload_mass_kg is added where the scenario puts its payload \
         ([payload] link and offset; the tip frame's origin without one), to the link's \
         inertial before the arm's dynamics and statics are built, while the servos' \
         references (gravity feed-forward, static stretch) keep the payload they were told \
         (the scenario's, or the run's payload_kg). Held still, the ropes carry the extra \
         weight m g l (l its lever arm about each joint): every pair's force changes by \
         m g l / r, the servos give way by r_m times that over kp and the ropes stretch by \
         it over their stiffness, so the joints sag, and a distal joint whose rope runs \
         over a sagging joint's relay turns with it; each run starts at rest there. Moving, \
         the joints' inertia grows by m l^2, so the arm's modes fall. Only data of an arm \
         reveal it (the arm_moves kind); the rig has no payload."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn site(&self) -> Site {
        Site::Link
    }
    fn applies_to(&self, kind: DataKind) -> bool {
        // Rig sweeps and rope specimens carry no payload.
        kind == DataKind::ArmMoves
    }
    fn on_payload(&self, args: Args<'_>, payload: &mut Payload) -> Result<(), DriveError> {
        check(self, args.values)?;
        payload.mass_kg += args.values[0];
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::Applied;
    use super::*;

    #[test]
    fn adds_its_mass_and_refuses_a_negative_payload() {
        let mut p = Payload { mass_kg: 5.0 };
        Applied::new(&PayloadMass, vec![-1.5])
            .unwrap()
            .apply_to_payload(&mut p)
            .unwrap();
        assert!((p.mass_kg - 3.5).abs() < 1e-15);
        // Zero leaves the payload bitwise as it was.
        let mut q = Payload { mass_kg: 0.1 + 0.2 };
        Applied::new(&PayloadMass, vec![0.0])
            .unwrap()
            .apply_to_payload(&mut q)
            .unwrap();
        assert_eq!(q.mass_kg.to_bits(), (0.1f64 + 0.2).to_bits());
        let err = Applied::new(&PayloadMass, vec![-6.0])
            .unwrap()
            .apply_to_payload(&mut Payload { mass_kg: 5.0 })
            .unwrap_err()
            .to_string();
        assert!(err.contains("below 0 kg"), "{err}");
        assert!(Applied::new(&PayloadMass, vec![2e3]).is_err());
    }
}
