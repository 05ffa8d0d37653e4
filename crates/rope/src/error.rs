//! Errors of the rope crate: each says what, where and what to do.

/// Everything that can go wrong building or running a rope law.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RopeError {
    /// A catalog or inline rope could not be parsed.
    #[error("{origin}: cannot parse the rope catalog: {message}")]
    Parse {
        /// File or table the text came from.
        origin: String,
        /// Parser message (carries the line and the key).
        message: String,
    },
    /// A catalog file could not be read.
    #[error("{path}: cannot read the rope catalog: {message}")]
    Io {
        /// Path of the file.
        path: String,
        /// OS message.
        message: String,
    },
    /// A rope name is not in the catalog.
    #[error(
        "unknown rope `{name}` (catalog {origin}); known ropes: {}. Use one of these names or define the rope inline",
        known.join(", ")
    )]
    UnknownRope {
        /// The name asked for.
        name: String,
        /// Catalog it was looked up in.
        origin: String,
        /// Names the catalog has.
        known: Vec<String>,
    },
    /// A constant is zero, negative or not finite.
    #[error("{origin}: rope `{rope}`: `{field}` = {value} must be a finite positive number (per-strain constants in N or N*s)")]
    BadConstant {
        /// File or table.
        origin: String,
        /// Rope name.
        rope: String,
        /// Offending key.
        field: String,
        /// Value found.
        value: f64,
    },
    /// Some but not all of k3, c2, c3 are given.
    #[error("{origin}: rope `{rope}` gives only some of k3, c2, c3: give all three (four-element model, Table VI) or none (elastic rope)")]
    IncompleteFourElement {
        /// File or table.
        origin: String,
        /// Rope name.
        rope: String,
    },
    /// The law asked for needs constants the rope does not have.
    #[error("rope `{rope}`: the {law} law needs `{missing}`, which the rope does not define; add it or choose another law ({hint})")]
    MissingConstant {
        /// Rope name.
        rope: String,
        /// Law asked for.
        law: String,
        /// Missing key.
        missing: String,
        /// What the user can do.
        hint: String,
    },
    /// A law parameter is outside its valid range.
    #[error("rope law parameter `{field}` = {value}: {reason}")]
    BadParameter {
        /// Parameter name.
        field: String,
        /// Value given.
        value: f64,
        /// Why it is invalid and what to do.
        reason: String,
    },
    /// The time step is outside what the integrator accepts.
    #[error("time step dt_s = {dt_s} must be finite and in (0, 1] s")]
    BadTimeStep {
        /// The step given.
        dt_s: f64,
    },
    /// The integration produced a non-finite value.
    #[error("rope integration blew up: {what} became {value} at strain {strain}; reduce dt_s or check the rope constants")]
    NonFinite {
        /// Which quantity.
        what: &'static str,
        /// Its value.
        value: f64,
        /// Total strain imposed at that step.
        strain: f64,
    },
}
