//! The rope catalog: the paper's measured constants, addressable by name.
//!
//! The shipped catalog is `robots/ropes.toml` (Tables I, IV and VI of the paper). Keys
//! follow the paper's symbols; every constant is *per unit strain* (`k1`, `k3`, `kp`
//! in N, `c2`, `c3` in N*s), so a rope of length `L` has spring rate `k/L` [N/m] and
//! dashpot rate `c/L` [N*s/m].

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::RopeError;

/// The catalog shipped with longreach (`robots/ropes.toml`).
pub const BUILTIN_CATALOG_TOML: &str = include_str!("../../../robots/ropes.toml");

/// Measured constants of one rope, per unit strain (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RopeParams {
    /// Catalog name (the TOML table name), e.g. `dyneema2`.
    #[serde(default, skip_serializing)]
    pub name: String,
    /// Free-text fiber and construction.
    #[serde(default)]
    pub fiber: String,
    /// Breaking load [N] (Table I).
    pub tensile_strength_n: f64,
    /// Linear mass [kg/m] (Table I).
    #[serde(default)]
    pub mass_per_length_kg_m: f64,
    /// Elastic coefficient of the instantaneous spring [N per unit strain] (Table VI, or k_s).
    #[serde(rename = "k1")]
    pub k1_n: f64,
    /// Retarded-elasticity spring [N] (Table VI). Absent for elastic ropes.
    #[serde(rename = "k3", default, skip_serializing_if = "Option::is_none")]
    pub k3_n: Option<f64>,
    /// Creep (Maxwell) dashpot [N*s] (Table VI). Absent for elastic ropes.
    #[serde(rename = "c2", default, skip_serializing_if = "Option::is_none")]
    pub c2_n_s: Option<f64>,
    /// Retarded-elasticity dashpot [N*s] (Table VI). Absent for elastic ropes.
    #[serde(rename = "c3", default, skip_serializing_if = "Option::is_none")]
    pub c3_n_s: Option<f64>,
    /// Spring parallel to Flory's ratchet [N] (Table IV). Absent: no plasticity data.
    #[serde(rename = "kp", default, skip_serializing_if = "Option::is_none")]
    pub kp_n: Option<f64>,
    /// k1 from the load-amplitude test [N] (Table IV), for reference.
    #[serde(rename = "k1_table4", default, skip_serializing_if = "Option::is_none")]
    pub k1_table4_n: Option<f64>,
    /// RMS of the paper's relaxation fit [N] (Table VI), for reference.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relaxation_fit_rms_n: Option<f64>,
}

impl RopeParams {
    /// True when the rope has the four visco-elastic constants (k1, c2, k3, c3).
    pub fn has_four_element(&self) -> bool {
        self.k3_n.is_some() && self.c2_n_s.is_some() && self.c3_n_s.is_some()
    }

    /// Checks every constant is finite and positive; `source` names the file or table
    /// for the error message.
    pub fn validate(&self, source: &str) -> Result<(), RopeError> {
        let mut fields: Vec<(&str, f64)> = vec![
            ("tensile_strength_n", self.tensile_strength_n),
            ("k1", self.k1_n),
        ];
        for (name, value) in [
            ("k3", self.k3_n),
            ("c2", self.c2_n_s),
            ("c3", self.c3_n_s),
            ("kp", self.kp_n),
        ] {
            if let Some(v) = value {
                fields.push((name, v));
            }
        }
        for (field, value) in fields {
            if !(value.is_finite() && value > 0.0) {
                return Err(RopeError::BadConstant {
                    origin: source.to_string(),
                    rope: self.name.clone(),
                    field: field.to_string(),
                    value,
                });
            }
        }
        if self.mass_per_length_kg_m < 0.0 || !self.mass_per_length_kg_m.is_finite() {
            return Err(RopeError::BadConstant {
                origin: source.to_string(),
                rope: self.name.clone(),
                field: "mass_per_length_kg_m".into(),
                value: self.mass_per_length_kg_m,
            });
        }
        let four = [self.k3_n, self.c2_n_s, self.c3_n_s];
        let present = four.iter().filter(|v| v.is_some()).count();
        if present != 0 && present != 3 {
            return Err(RopeError::IncompleteFourElement {
                origin: source.to_string(),
                rope: self.name.clone(),
            });
        }
        Ok(())
    }
}

/// A set of named ropes.
#[derive(Debug, Clone, Default)]
pub struct Catalog {
    ropes: BTreeMap<String, RopeParams>,
    source: String,
}

impl Catalog {
    /// The catalog shipped with longreach (`robots/ropes.toml`).
    pub fn builtin() -> Self {
        // The shipped file is checked by this crate's tests; a failure here is a build defect.
        Self::from_toml_str(BUILTIN_CATALOG_TOML, "robots/ropes.toml")
            .unwrap_or_else(|e| panic!("the built-in rope catalog is invalid: {e}"))
    }

    /// Parses a catalog from TOML text; `source` names it in errors.
    pub fn from_toml_str(text: &str, source: &str) -> Result<Self, RopeError> {
        let raw: BTreeMap<String, RopeParams> =
            toml::from_str(text).map_err(|e| RopeError::Parse {
                origin: source.to_string(),
                message: e.to_string(),
            })?;
        let mut ropes = BTreeMap::new();
        for (name, mut params) in raw {
            params.name = name.clone();
            params.validate(source)?;
            ropes.insert(name, params);
        }
        Ok(Self {
            ropes,
            source: source.to_string(),
        })
    }

    /// Reads a catalog file.
    pub fn from_file(path: &Path) -> Result<Self, RopeError> {
        let text = std::fs::read_to_string(path).map_err(|e| RopeError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Looks a rope up by name (case-insensitive).
    pub fn get(&self, name: &str) -> Result<&RopeParams, RopeError> {
        let key = name.to_ascii_lowercase();
        self.ropes.get(&key).ok_or_else(|| RopeError::UnknownRope {
            name: name.to_string(),
            origin: self.source.clone(),
            known: self.names().map(str::to_string).collect(),
        })
    }

    /// Rope names in sorted order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.ropes.keys().map(String::as_str)
    }

    /// All ropes in name order.
    pub fn ropes(&self) -> impl Iterator<Item = &RopeParams> {
        self.ropes.values()
    }
}
