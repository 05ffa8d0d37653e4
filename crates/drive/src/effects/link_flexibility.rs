//! Bending of an arm's links: the compliance of a long carbon tube between its joints.

use super::{Args, DataKind, Effect, EffectParam, LinkBending, Site};
use crate::DriveError;

/// The links of an arm bend: their bending stiffness `EI` scaled and their structural
/// damping ratio set (an arm scenario's `[[flex]]` links, crates/arm `flex`).
#[derive(Debug)]
pub struct LinkFlexibility;

const PARAMS: &[EffectParam] = &[
    EffectParam {
        name: "ei_scale",
        unit: "1",
        default: 1.0,
        lower: 1e-3,
        upper: 1e3,
        log_scale: true,
        fitted: true,
    },
    EffectParam {
        name: "damping_ratio",
        unit: "1",
        default: 0.01,
        lower: 0.0,
        upper: 0.5,
        log_scale: false,
        fitted: true,
    },
];

impl Effect for LinkFlexibility {
    fn name(&self) -> &'static str {
        "link_flexibility"
    }
    fn doc(&self) -> &'static str {
        "The links of a long-reach arm are tubes that bend: under their own weight and \
         the payload the tip sags by w L^4 / (8 E I) + P L^3 / (3 E I) per link, below \
         where the joint angles put it, and after a move the links' first bending modes \
         ring with the ropes, at a frequency below the rope-only resonance of the arm. \
         The effect scales each flexible link's bending stiffness E I (ei_scale) and sets \
         the structural damping ratio of its bending modes: a stiffer or softer tube \
         than its datasheet, a joint housing that adds compliance, damping from bonded \
         joints and cables."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn site(&self) -> Site {
        Site::Link
    }
    fn applies_to(&self, kind: DataKind) -> bool {
        // The rig's sweeps, relaxation and cyclic tests have no link to bend; on arm
        // moves the arm plant scales the scenario's flexible links (`[[flex]]`) and
        // leaves the effect out of the candidates of a rigid arm (no E I to scale).
        kind == DataKind::ArmMoves
    }
    fn on_link(&self, args: Args<'_>, link: &mut LinkBending) -> Result<bool, DriveError> {
        link.ei_n_m2 *= args.values[0];
        link.damping_ratio = args.values[1];
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{find, Applied};
    use super::*;

    #[test]
    fn scales_the_stiffness_and_sets_the_damping() {
        let e = find("link_flexibility").expect("registered");
        assert_eq!(e.site(), Site::Link);
        let a = Applied::new(e, vec![2.0, 0.03]).unwrap();
        let mut l = LinkBending {
            ei_n_m2: 1e6,
            damping_ratio: 0.0,
        };
        assert!(a.apply_to_link(&mut l).unwrap());
        assert!((l.ei_n_m2 - 2e6).abs() < 1e-9);
        assert!((l.damping_ratio - 0.03).abs() < 1e-15);
        assert!(Applied::new(e, vec![0.0, 0.01]).is_err());
    }
}
