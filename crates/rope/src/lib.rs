//! Rope laws of longreach: the elastic, four-element (Burgers) and Flory models of the
//! paper (Figs. 1-2, eqs. 1-7), the rope catalog, and an unconditionally stable time
//! step for each. No physics engine here: a rope is driven by the strain its
//! transmission imposes and answers with its tension.
//!
//! Every constant is per unit strain, as in the paper (`k` in N, `c` in N*s); a rope of
//! length `L` has spring rate `k/L` and dashpot rate `c/L`.
//!
//! ```
//! use longreach_rope::{Catalog, LawKind, RopeLaw, RopeStepper};
//! let catalog = Catalog::builtin();
//! let dyneema = catalog.get("dyneema2").unwrap();
//! let law = RopeLaw::from_params(dyneema, LawKind::FourElement).unwrap();
//! let stepper = RopeStepper::new(law, 1e-3).unwrap();
//! let mut state = stepper.instant_strain_state(0.015);
//! let tensions = stepper.run_strain_history(&mut state, &[0.015; 1000]).unwrap();
//! assert!(tensions[999] < 0.015 * dyneema.k1_n); // the tension relaxes (eq. 6)
//! ```

mod catalog;
mod error;
mod law;
mod relaxation;
mod table;

pub use catalog::{Catalog, RopeParams, BUILTIN_CATALOG_TOML};
pub use error::RopeError;
pub use law::{
    KelvinElement, LawKind, NonlinearCreep, Piece, PreparedStep, RopeLaw, RopeState, RopeStepper,
    MAX_KELVIN,
};
pub use relaxation::{relaxation_tension_n, rms_error};
pub use table::{reached_during, Table, TableFile, MAX_KNOTS};
