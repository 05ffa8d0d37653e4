//! Models a user believes in: a rope law, base parameters (known or fitted, global or
//! per run) and a list of effects from the registry ([`longreach_drive::effects`]),
//! read from and written to TOML model files (format: `docs/models.md`).

use longreach_drive::effects::{self, check_table, Applied, DataKind, Effect, Shape, Site, Target};
use longreach_drive::DriveError;
use longreach_rope::{Catalog, LawKind, RopeError, RopeLaw, RopeParams, Table};
use longreach_scenario::spec::field_error;
use longreach_scenario::ScenarioError;
use serde::Serialize;

use crate::dataset::{Dataset, DatasetKind};
use crate::fitting::{FitResult, ParamSpec};

/// One parameter of a model: its value, bounds, and whether it is fitted.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamDef {
    /// Name (`k1_scale`, `c2`, `stiffening_per_n`, ...).
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Value (the starting value when fitted).
    pub value: f64,
    /// Per-run values after a per-run fit (`None` for a global parameter).
    pub run_values: Option<Vec<f64>>,
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// Fitted on a log scale.
    pub log_scale: bool,
    /// Fitted (true) or known (false).
    pub fit: bool,
    /// One value per run instead of one for the whole dataset.
    pub per_run: bool,
    /// What the value sets (typed when the model is read: a fit changes numbers, never
    /// rebuilds anything through a parameter's name).
    #[serde(skip)]
    pub role: Role,
}

/// What a model parameter sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Role {
    /// A base parameter of the plant.
    Base(BaseParam),
    /// A parameter of the model's effect that owns it (by position).
    #[default]
    Effect,
    /// A quantity of an effect's shape-free table ([`ShapeUse`]).
    Shape,
}

/// The base parameters a model may set, by what they set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum BaseParam {
    /// `k1_scale`: multiplies the catalog k1.
    K1Scale,
    /// `k1` [N].
    K1,
    /// `c1` [N*s] (internal damping, a dashpot parallel to k1).
    C1,
    /// `c2` [N*s] (creep dashpot).
    C2,
    /// `k3` [N] (the first Kelvin element's spring).
    K3,
    /// `c3` [N*s] (its dashpot).
    C3,
    /// `kp` [N] (Flory's ratchet spring).
    Kp,
    /// `output_damping_n_m_s` [N*m*s]: the rig's C.
    OutputDamping,
}

impl BaseParam {
    /// Every base parameter.
    pub const ALL: [BaseParam; 8] = [
        Self::K1Scale,
        Self::K1,
        Self::C1,
        Self::C2,
        Self::K3,
        Self::C3,
        Self::Kp,
        Self::OutputDamping,
    ];

    /// Name, as in model files.
    pub fn name(self) -> &'static str {
        match self {
            Self::K1Scale => "k1_scale",
            Self::K1 => "k1",
            Self::C1 => "c1",
            Self::C2 => "c2",
            Self::K3 => "k3",
            Self::C3 => "c3",
            Self::Kp => "kp",
            Self::OutputDamping => "output_damping_n_m_s",
        }
    }

    /// Unit.
    pub fn unit(self) -> &'static str {
        match self {
            Self::K1Scale => "1",
            Self::K1 | Self::K3 | Self::Kp => "N",
            Self::C1 | Self::C2 | Self::C3 => "N*s",
            Self::OutputDamping => "N*m*s",
        }
    }

    /// The base parameter called `name` in a model file.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Sets value `v` in the plant parameters `p`.
    pub fn apply(self, v: f64, p: &mut PlantParams) -> Result<(), ModelError> {
        let law = &mut p.law;
        match self {
            Self::K1Scale => law.k1_n *= v,
            Self::K1 => law.k1_n = v,
            Self::C1 => law.c1_n_s = v,
            Self::C2 => law.c2_n_s = Some(v),
            Self::K3 | Self::C3 => {
                let el = law
                    .kelvin
                    .first_mut()
                    .ok_or_else(|| ModelError::NeedsKelvinElement {
                        param: self.name().to_string(),
                    })?;
                if self == Self::K3 {
                    el.k_n = v;
                } else {
                    el.c_n_s = v;
                }
            }
            Self::Kp => law.kp_n = Some(v),
            Self::OutputDamping => p.output_damping_n_m_s = Some(v),
        }
        Ok(())
    }
}

/// The numbers a model gives a plant for one run ([`Model::plant_params`]): the rope
/// law with the base parameters and every rope-law effect applied, the rig's output
/// damping when the model sets it, and the effects at the plant's other sites (relay
/// pulleys, joints) with their values.
#[derive(Debug, Clone)]
pub struct PlantParams {
    /// The rope law.
    pub law: RopeLaw,
    /// The rig's C when the model sets it, N*m*s.
    pub output_damping_n_m_s: Option<f64>,
    /// Effects at sites other than the rope law, for the plant to apply when it is
    /// built.
    pub effects: Vec<Applied>,
    /// The base parameters with their values for this run, in the model's order
    /// (already applied to `law`): a plant with ropes of its own (the arm, one law per
    /// pair) applies them to each of its laws.
    pub base: Vec<(BaseParam, f64)>,
    /// The rope-law effects (already applied to `law`), for the same plants.
    pub rope_effects: Vec<Applied>,
    /// For each of [`Self::effects`], where on an arm it is restricted to
    /// ([`EffectUse::at`]: driven joints, or flexible links for an effect on a link's
    /// bending); `None`: everywhere. A rope-law effect restricted to some joints is in
    /// `effects`, not applied to `law`.
    pub effect_at: Vec<Option<Vec<String>>>,
}

impl ParamDef {
    /// A fitted global base parameter on a log scale.
    pub fn base(param: BaseParam, value: f64, lower: f64, upper: f64) -> Self {
        Self {
            name: param.name().into(),
            unit: param.unit().into(),
            value,
            run_values: None,
            lower,
            upper,
            log_scale: true,
            fit: true,
            per_run: false,
            role: Role::Base(param),
        }
    }

    /// Value for run `run`.
    pub fn value_for(&self, run: usize) -> f64 {
        self.run_values
            .as_ref()
            .and_then(|v| v.get(run).copied())
            .unwrap_or(self.value)
    }
}

/// An effect included in a model, with its parameters.
#[derive(Debug, Clone)]
pub struct EffectUse {
    /// The registered effect.
    pub effect: &'static dyn Effect,
    /// Its parameters, in the effect's order.
    pub params: Vec<ParamDef>,
    /// Its shape-free form, when the model holds the effect's law as a table
    /// ([`longreach_drive::effects::Shape`]); the parameters it replaces are held.
    pub shape: Option<ShapeUse>,
    /// On an arm, where these values act: the driven joints (names, as the dataset's
    /// columns) whose pairs and bearings take them, or for an effect on a link's
    /// bending ([`longreach_drive::effects::bends_links`]) the flexible links (URDF
    /// names); `None`: every driven joint, or every flexible link. The same effect may
    /// be in a model several times, on disjoint joints or links: its values per joint
    /// or per link. In model files the list is `joints` or `links` ([`at_key`]).
    pub at: Option<Vec<String>>,
}

impl EffectUse {
    /// The effect's name with its joints when it is restricted to some
    /// (`joint_friction@j2+j5`): how its parameters are named in fits and reports.
    pub fn label(&self) -> String {
        match &self.at {
            None => self.effect.name().to_string(),
            Some(j) => format!("{}@{}", self.effect.name(), j.join("+")),
        }
    }

    /// The fitted name of parameter `p` of this effect: `p`'s own, with `@joints` when
    /// the effect is restricted to some.
    pub fn param_name(&self, p: &ParamDef) -> String {
        match &self.at {
            None => p.name.clone(),
            Some(j) => format!("{}@{}", p.name, j.join("+")),
        }
    }
}

/// The shape-free form of an effect in a model: the table's knots (fixed: placed over
/// the range the data visits) and its values, fitted through [`Self::params`] (one per
/// knot, the first only when the shape does not fix it; for a law that never falls,
/// the rise from the previous knot, >= 0).
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeUse {
    /// The effect's shape.
    pub shape: Shape,
    /// Knots, increasing from 0, in the unit of the shape's argument.
    pub knots: Vec<f64>,
    /// The fitted quantities (see above), as model parameters.
    pub params: Vec<ParamDef>,
}

impl ShapeUse {
    /// The lower bound of a table value fitted on a log scale (a law that may fall:
    /// its values, not its rises, are fitted).
    pub fn value_lower_bound(shape: &Shape) -> f64 {
        shape.max_value * 1e-9
    }

    /// The shape-free form of `shape` with `values` at `knots` (every parameter fitted
    /// when `fit`), checked against the shape.
    pub fn new(
        effect: &dyn Effect,
        shape: Shape,
        knots: &[f64],
        values: &[f64],
        fit: bool,
    ) -> Result<Self, ModelError> {
        let table = Table::new(knots, values).map_err(|source| ModelError::Effect {
            effect: effect.name(),
            source: source.into(),
        })?;
        check_table(effect.name(), &shape, &table).map_err(|source| ModelError::Effect {
            effect: effect.name(),
            source,
        })?;
        let arg = shape.argument.name();
        let mut params = Vec::new();
        // A value is positive (log scale).
        let def = |name: String, value: f64, lower: f64, log_scale: bool| ParamDef {
            name,
            unit: shape.unit.into(),
            value,
            run_values: None,
            lower,
            upper: shape.max_value,
            log_scale,
            fit,
            per_run: false,
            role: Role::Shape,
        };
        if shape.value_at_zero.is_none() {
            params.push(def(
                format!("{}@{arg}=0", shape.value),
                values[0],
                Self::value_lower_bound(&shape),
                true,
            ));
        }
        for i in 1..knots.len() {
            params.push(if shape.non_decreasing {
                // a rise may be 0 (a flat stretch): a linear scale (on a log scale a
                // rise near 0 would freeze there)
                def(
                    format!("{}_rise@{arg}={}", shape.value, knots[i]),
                    (values[i] - values[i - 1]).max(0.0),
                    0.0,
                    false,
                )
            } else {
                def(
                    format!("{}@{arg}={}", shape.value, knots[i]),
                    values[i],
                    Self::value_lower_bound(&shape),
                    true,
                )
            });
        }
        Ok(Self {
            shape,
            knots: knots.to_vec(),
            params,
        })
    }

    /// The table's values for run `run` (knot by knot): the first (fixed or fitted),
    /// then each knot's value, or for a law that never falls the previous one plus its
    /// rise.
    pub fn values_for(&self, run: usize) -> Vec<f64> {
        let mut y = Vec::with_capacity(self.knots.len());
        let mut p = self.params.iter();
        let first = match self.shape.value_at_zero {
            Some(v) => v,
            None => p.next().map_or(f64::NAN, |d| d.value_for(run)),
        };
        y.push(first);
        for d in p {
            let v = d.value_for(run);
            let last = *y.last().unwrap_or(&first);
            y.push(if self.shape.non_decreasing {
                last + v
            } else {
                v
            });
        }
        y
    }

    /// The table for run `run`.
    pub fn table_for(&self, run: usize) -> Result<Table, RopeError> {
        Table::new(&self.knots, &self.values_for(run))
    }

    /// The `[effect.shape]` table of a model file: the knots under the argument's name,
    /// the values under the value's name, and whether they are fitted.
    pub fn to_toml(&self) -> String {
        let list = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:e}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!(
            "\n[effect.shape]\n{} = [{}]\n{} = [{}]\nfit = {}\n",
            self.shape.argument.name(),
            list(&self.knots),
            self.shape.value,
            list(&self.values_for(0)),
            self.params.iter().any(|p| p.fit)
        )
    }
}

/// A model of a dataset: rope law, base parameters, effects.
#[derive(Debug, Clone)]
pub struct Model {
    /// Rope name (catalog).
    pub rope: String,
    /// Law kind.
    pub law_kind: LawKind,
    /// Law built from the catalog constants (base parameters are applied on top).
    pub law: RopeLaw,
    /// Base parameters: `k1_scale` multiplies k1; `k1`, `c1`, `c2`, `k3`, `c3`, `kp`
    /// set the constant; `output_damping_n_m_s` sets the rig's C.
    pub base: Vec<ParamDef>,
    /// Effects.
    pub effects: Vec<EffectUse>,
}

/// The kind of a dataset as the effect registry sees it.
pub fn data_kind(ds: &Dataset) -> DataKind {
    match ds.kind {
        DatasetKind::SineSweep(_) => DataKind::SineSweep,
        DatasetKind::Relaxation(_) => DataKind::Relaxation,
        DatasetKind::Cyclic(_) => DataKind::Cyclic,
        DatasetKind::ArmMoves(_) => DataKind::ArmMoves,
    }
}

/// Rope name of a dataset.
pub fn dataset_rope(ds: &Dataset) -> &str {
    match &ds.kind {
        DatasetKind::SineSweep(s) => &s.rig.rope,
        DatasetKind::Relaxation(r) => &r.specimen.rope,
        DatasetKind::Cyclic(c) => &c.specimen.rope,
        DatasetKind::ArmMoves(a) => &a.rope,
    }
}

fn catalog_rope(name: &str) -> Result<RopeParams, RopeError> {
    Catalog::builtin().get(name).cloned()
}

/// What a model could not be built from, or why it cannot give the rope law or the rig
/// of a run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// A model file problem, located.
    #[error("{0}")]
    File(#[from] ScenarioError),
    /// The rope is not in the catalog, its constants give no law of the kind asked
    /// for, or the law with the model's values is invalid.
    #[error(transparent)]
    Rope(#[from] RopeError),
    /// `k3` or `c3` set on a law without a Kelvin-Voigt element (an elastic law).
    #[error("`{param}` needs a four-element or Flory law")]
    NeedsKelvinElement {
        /// The base parameter (`k3` or `c3`).
        param: String,
    },
    /// An effect refused its parameter values (on the rope law or on the rig).
    #[error("effect {effect}: {source}")]
    Effect {
        /// The effect's registered name.
        effect: &'static str,
        /// The effect's complaint.
        #[source]
        source: DriveError,
    },
}

impl Model {
    /// The paper's model of the dataset (the baseline): four-element for fiber ropes,
    /// elastic for steel; sweeps fit one global `k1_scale`; relaxation and cyclic tests
    /// fit the law's constants (k1, c2, k3, c3 as in the paper, or k1 alone if elastic).
    pub fn baseline(ds: &Dataset) -> Result<Model, ModelError> {
        let rope = dataset_rope(ds).to_string();
        let params = catalog_rope(&rope)?;
        let law_kind = LawKind::default_for(&params);
        let law = RopeLaw::from_params(&params, law_kind)?;
        let base = match ds.kind {
            DatasetKind::SineSweep(_) | DatasetKind::ArmMoves(_) => {
                vec![ParamDef::base(BaseParam::K1Scale, 1.0, 0.2, 5.0)]
            }
            _ => law_constants(&law),
        };
        Ok(Model {
            rope,
            law_kind,
            law,
            base,
            effects: Vec::new(),
        })
    }

    /// Every fitted parameter slot: `(index in base or effect, param index, run)`.
    pub fn free_slots(&self, n_runs: usize) -> Vec<Slot> {
        let mut out = Vec::new();
        let all = self
            .base
            .iter()
            .enumerate()
            .map(|(j, p)| (Owner::Base, j, p))
            .chain(self.effects.iter().enumerate().flat_map(|(e, u)| {
                u.params
                    .iter()
                    .enumerate()
                    .map(move |(j, p)| (Owner::Effect(e), j, p))
            }))
            .chain(self.effects.iter().enumerate().flat_map(|(e, u)| {
                u.shape.iter().flat_map(move |sh| {
                    sh.params
                        .iter()
                        .enumerate()
                        .map(move |(j, p)| (Owner::Shape(e), j, p))
                })
            }));
        for (owner, j, p) in all {
            if !p.fit {
                continue;
            }
            if p.per_run {
                for r in 0..n_runs {
                    out.push(Slot {
                        owner,
                        index: j,
                        run: Some(r),
                    });
                }
            } else {
                out.push(Slot {
                    owner,
                    index: j,
                    run: None,
                });
            }
        }
        out
    }

    /// The fitted name of `p`, a parameter of `owner`: its own, with the joints of an
    /// effect restricted to some ([`EffectUse::param_name`]).
    pub fn param_name(&self, owner: Owner, p: &ParamDef) -> String {
        match owner {
            Owner::Base => p.name.clone(),
            Owner::Effect(e) | Owner::Shape(e) => self.effects[e].param_name(p),
        }
    }

    /// The parameter in slot `s`.
    pub fn param(&self, s: &Slot) -> &ParamDef {
        match s.owner {
            Owner::Base => &self.base[s.index],
            Owner::Effect(e) => &self.effects[e].params[s.index],
            Owner::Shape(e) => match &self.effects[e].shape {
                Some(sh) => &sh.params[s.index],
                None => &self.effects[e].params[s.index],
            },
        }
    }

    fn param_mut(&mut self, s: &Slot) -> &mut ParamDef {
        match s.owner {
            Owner::Base => &mut self.base[s.index],
            Owner::Effect(e) => &mut self.effects[e].params[s.index],
            Owner::Shape(e) => {
                let u = &mut self.effects[e];
                match u.shape.as_mut() {
                    Some(sh) => &mut sh.params[s.index],
                    None => &mut u.params[s.index],
                }
            }
        }
    }

    /// True when slot `s` is the rise of a table that never falls ([`ShapeUse`]):
    /// linear, bounded below by 0 and above by the shape's largest value.
    pub fn is_rise(&self, s: &Slot) -> bool {
        let p = self.param(s);
        matches!(s.owner, Owner::Shape(_)) && !p.log_scale && p.lower == 0.0
    }

    /// Fitting specs of the free slots (starting at the current values).
    pub fn fit_specs(&self, n_runs: usize) -> Vec<ParamSpec> {
        self.free_slots(n_runs)
            .iter()
            .map(|s| {
                let p = self.param(s);
                let name = self.param_name(s.owner, p);
                let name = match s.run {
                    Some(r) => format!("{name}[{r}]"),
                    None => name,
                };
                let v0 = s.run.map_or(p.value, |r| p.value_for(r));
                let init = crate::fitting::strictly_inside(v0, p.lower, p.upper);
                ParamSpec {
                    name,
                    unit: p.unit.clone(),
                    initial: init,
                    lower: p.lower,
                    upper: p.upper,
                    log_scale: p.log_scale && p.lower >= 0.0 && init > 0.0,
                }
            })
            .collect()
    }

    /// The model with every fitted effect parameter that sits on one of its bounds
    /// (within the margin [`crate::fitting::strictly_inside`] keeps a start from them)
    /// back at the effect's default; `None` when none does. A least-squares fit that
    /// reaches a bound or starts on one stays there (the map of a bounded parameter is
    /// flat at its bounds): [`crate::analysis::fit_model_from`] restarts such values
    /// from the defaults when the model is closer to the data there.
    pub fn with_bound_values_reset(&self, n_runs: usize) -> Option<Model> {
        let mut any = false;
        let x: Vec<f64> = self
            .free_slots(n_runs)
            .iter()
            .map(|s| {
                let p = self.param(s);
                let v = s.run.map_or(p.value, |r| p.value_for(r));
                let default = match s.owner {
                    Owner::Effect(e) => self.effects[e].effect.params().get(s.index),
                    _ => None,
                };
                // (bit for bit: a value the margin moves at all is on a bound)
                let on_bound =
                    crate::fitting::strictly_inside(v, p.lower, p.upper).to_bits() != v.to_bits();
                match default {
                    Some(d) if on_bound => {
                        any = true;
                        d.default
                    }
                    _ => v,
                }
            })
            .collect();
        any.then(|| self.with_values(&x, n_runs))
    }

    /// The model with the free parameters set to `x` (in [`Self::free_slots`] order).
    pub fn with_values(&self, x: &[f64], n_runs: usize) -> Model {
        let mut m = self.clone();
        for (s, &v) in self.free_slots(n_runs).iter().zip(x) {
            let p = m.param_mut(s);
            let v = v.clamp(p.lower, p.upper);
            match s.run {
                None => p.value = v,
                Some(r) => {
                    let vals = p.run_values.get_or_insert_with(|| vec![p.value; n_runs]);
                    if r < vals.len() {
                        vals[r] = v;
                    }
                }
            }
        }
        m
    }

    /// The numbers the model gives a plant for run `run` ([`PlantParams`]): base
    /// parameters and rope-law effects applied to the law, the other effects with their
    /// values.
    pub fn plant_params(&self, run: usize) -> Result<PlantParams, ModelError> {
        let mut p = PlantParams {
            law: self.law.clone(),
            output_damping_n_m_s: None,
            effects: Vec::new(),
            base: Vec::new(),
            rope_effects: Vec::new(),
            effect_at: Vec::new(),
        };
        for b in &self.base {
            if let Role::Base(param) = b.role {
                param.apply(b.value_for(run), &mut p)?;
                p.base.push((param, b.value_for(run)));
            }
        }
        for u in &self.effects {
            let vals: Vec<f64> = u.params.iter().map(|q| q.value_for(run)).collect();
            let applied = match &u.shape {
                None => Applied::new(u.effect, vals),
                Some(sh) => {
                    let table = sh.table_for(run)?;
                    Applied::shaped(u.effect, vals, table)
                }
            }
            .map_err(|source| ModelError::Effect {
                effect: u.effect.name(),
                source,
            })?;
            if u.effect.site() == Site::RopeLaw && u.at.is_none() {
                applied
                    .apply_to_law(&mut p.law)
                    .map_err(|source| ModelError::Effect {
                        effect: u.effect.name(),
                        source,
                    })?;
                p.rope_effects.push(applied);
            } else {
                p.effects.push(applied);
                p.effect_at.push(u.at.clone());
            }
        }
        p.law.validate()?;
        Ok(p)
    }

    /// Rope law (with the rope-law effects) and rig damping override of run `run`
    /// ([`Self::plant_params`]).
    pub fn law_for_run(&self, run: usize) -> Result<(RopeLaw, Option<f64>), ModelError> {
        let p = self.plant_params(run)?;
        Ok((p.law, p.output_damping_n_m_s))
    }

    /// The model plus `effect` with its default parameters, all fitted.
    pub fn with_effect(&self, effect: &'static dyn Effect) -> Model {
        let mut m = self.clone();
        m.effects.push(EffectUse {
            effect,
            params: effect
                .params()
                .iter()
                .map(|p| ParamDef {
                    name: p.name.into(),
                    unit: p.unit.into(),
                    value: p.default,
                    run_values: None,
                    lower: p.lower,
                    upper: p.upper,
                    log_scale: p.log_scale,
                    fit: p.fitted,
                    per_run: false,
                    role: Role::Effect,
                })
                .collect(),
            shape: None,
            at: None,
        });
        m
    }

    /// The model with effect number `e` in its shape-free form `shape` (the parameters
    /// the table replaces held, not fitted).
    pub fn with_shape(&self, e: usize, shape: ShapeUse) -> Model {
        let mut m = self.clone();
        let u = &mut m.effects[e];
        for p in u.params.iter_mut() {
            if shape.shape.replaces.contains(&p.name.as_str()) {
                p.fit = false;
                p.run_values = None;
            }
        }
        u.shape = Some(shape);
        m
    }

    /// The fit flags of every effect's table values, effect by effect (empty for an
    /// effect without a table).
    pub fn shape_fit_flags(&self) -> Vec<Vec<bool>> {
        self.effects
            .iter()
            .map(|u| {
                u.shape
                    .as_ref()
                    .map(|s| s.params.iter().map(|p| p.fit).collect())
                    .unwrap_or_default()
            })
            .collect()
    }

    /// The model with the fit flags of its first effects' table values set to `flags`
    /// (as [`Self::shape_fit_flags`] gives them); effects beyond `flags` unchanged.
    pub fn with_shape_fit_flags(&self, flags: &[Vec<bool>]) -> Model {
        let mut m = self.clone();
        for (u, f) in m.effects.iter_mut().zip(flags) {
            if let Some(s) = u.shape.as_mut() {
                for (p, &fit) in s.params.iter_mut().zip(f) {
                    p.fit = fit;
                }
            }
        }
        m
    }

    /// True when the model already holds `effect` (in its list or in its law).
    pub fn has_effect(&self, effect: &dyn Effect) -> bool {
        self.effects.iter().any(|u| effects::same(u.effect, effect))
            || self.law_for_run(0).is_ok_and(|(law, _)| {
                effect.present_in(&Target {
                    law: &law,
                    pair: None,
                    joint_effects: &[],
                })
            })
    }

    /// Named values of every parameter (per-run ones as `name[run]`), sorted by name.
    pub fn named_values(&self) -> Vec<(String, f64)> {
        let mut out = Vec::new();
        let all = self
            .base
            .iter()
            .map(|p| (p.name.clone(), p))
            .chain(
                self.effects
                    .iter()
                    .flat_map(|u| u.params.iter().map(move |p| (u.param_name(p), p))),
            )
            .chain(self.effects.iter().flat_map(|u| {
                u.shape
                    .iter()
                    .flat_map(move |sh| sh.params.iter().map(move |p| (u.param_name(p), p)))
            }));
        for (name, p) in all {
            match &p.run_values {
                Some(v) if p.per_run => {
                    for (r, x) in v.iter().enumerate() {
                        out.push((format!("{name}[{r}]"), *x));
                    }
                }
                _ => out.push((name, p.value)),
            }
        }
        out
    }

    /// The model as a model file (TOML text).
    pub fn to_toml(&self, comment: &str) -> String {
        self.to_toml_with_fit(comment, None)
    }

    /// The model as a model file, with the 95% interval of every parameter `fit`
    /// fitted (`interval_95 = [lower, upper]`, a list of them for a per-run parameter;
    /// the reader ignores the key).
    pub fn to_toml_with_fit(&self, comment: &str, fit: Option<&FitResult>) -> String {
        let interval = |name: &str| -> Option<(String, &'static str)> {
            let r = fit?;
            let i = r.names.iter().position(|n| n == name)?;
            let (lo, hi) = r.interval_95[i];
            Some((
                format!("[{lo:e}, {hi:e}]"),
                r.interval_clipped[i].as_str().unwrap_or(""),
            ))
        };
        let interval_line = |name: &str, p: &ParamDef| -> Option<String> {
            let (text, clipped) = match &p.run_values {
                Some(v) if p.per_run => {
                    let each: Option<Vec<(String, &str)>> = (0..v.len())
                        .map(|r| interval(&format!("{name}[{r}]")))
                        .collect();
                    let each = each?;
                    let clipped = each.iter().any(|(_, c)| !c.is_empty());
                    let list: Vec<String> = each.into_iter().map(|(t, _)| t).collect();
                    (
                        format!("[{}]", list.join(", ")),
                        if clipped { "some" } else { "" },
                    )
                }
                _ => interval(name)?,
            };
            let note = match clipped {
                "" => String::new(),
                "both" => ", clipped at both bounds".into(),
                "some" => ", some clipped at a bound".into(),
                side => format!(", clipped at the {side} bound"),
            };
            Some(format!(
                "interval_95 = {text}   # 95% interval{note} (not read)\n"
            ))
        };
        let mut s = String::new();
        for line in comment.lines() {
            s.push_str(&format!("# {line}\n"));
        }
        s.push_str(&format!(
            "rope = \"{}\"\nlaw = \"{}\"\n",
            self.rope,
            self.law_kind.as_str()
        ));
        let param = |s: &mut String, prefix: &str, name: &str, p: &ParamDef| {
            s.push_str(&format!("\n[{prefix}.{}]\n", p.name));
            s.push_str(&format!("value = {:e}\n", p.value));
            if let Some(v) = &p.run_values {
                let list: Vec<String> = v.iter().map(|x| format!("{x:e}")).collect();
                s.push_str(&format!("run_values = [{}]\n", list.join(", ")));
            }
            s.push_str(&format!(
                "fit = {}\nlower = {:e}\nupper = {:e}\nper_run = {}\n",
                p.fit, p.lower, p.upper, p.per_run
            ));
            if let Some(line) = interval_line(name, p) {
                s.push_str(&line);
            }
        };
        for p in &self.base {
            param(&mut s, "params", &p.name, p);
        }
        for u in &self.effects {
            s.push_str(&format!("\n[[effect]]\nname = \"{}\"\n", u.effect.name()));
            if let Some(j) = &u.at {
                let list: Vec<String> = j.iter().map(|n| format!("\"{n}\"")).collect();
                s.push_str(&format!("{} = [{}]\n", at_key(u.effect), list.join(", ")));
            }
            for p in &u.params {
                param(&mut s, "effect.params", &u.param_name(p), p);
            }
            if let Some(sh) = &u.shape {
                s.push_str(&sh.to_toml());
            }
        }
        s
    }

    /// Reads a model file. `ds` supplies the default rope and baseline parameters.
    pub fn from_toml(text: &str, file: &str, ds: &Dataset) -> Result<Model, ModelError> {
        let doc: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| longreach_scenario::spec::toml_error(text, file, &e))?;
        let err = |field: &str, msg: String, fix: &str| {
            ModelError::File(field_error(text, file, field, msg, fix))
        };
        for key in doc.keys() {
            if !["rope", "law", "params", "effect"].contains(&key.as_str()) {
                return Err(err(
                    key,
                    format!("unknown key `{key}`"),
                    "a model file holds rope, law, [params.NAME] tables and [[effect]] tables (docs/models.md)",
                ));
            }
        }
        let rope = match doc.get("rope") {
            None => dataset_rope(ds).to_string(),
            Some(toml::Value::String(s)) => s.clone(),
            Some(_) => {
                return Err(err(
                    "rope",
                    "must be a catalog name in quotes".into(),
                    "write rope = \"dyneema2\"",
                ))
            }
        };
        let params = catalog_rope(&rope).map_err(|e| {
            err(
                "rope",
                e.to_string(),
                "use a name listed by `longreach ropes`",
            )
        })?;
        let law_kind = match doc.get("law") {
            None => LawKind::default_for(&params),
            Some(toml::Value::String(s)) => match s.as_str() {
                "elastic" => LawKind::Elastic,
                "four_element" => LawKind::FourElement,
                "flory" => LawKind::Flory,
                _ => {
                    return Err(err(
                        "law",
                        format!("unknown law `{s}`"),
                        "use elastic, four_element or flory",
                    ))
                }
            },
            Some(_) => {
                return Err(err(
                    "law",
                    "must be a string".into(),
                    "use law = \"four_element\"",
                ))
            }
        };
        let law = RopeLaw::from_params(&params, law_kind).map_err(|e| {
            err(
                "law",
                e.to_string(),
                "choose a law the rope has constants for",
            )
        })?;
        let mut base = Vec::new();
        if let Some(v) = doc.get("params") {
            let t = v.as_table().ok_or_else(|| {
                err(
                    "params",
                    "must be a table".into(),
                    "write [params.k1_scale]",
                )
            })?;
            for (name, val) in t {
                let Some(param) = BaseParam::from_name(name) else {
                    return Err(err(
                        &format!("params.{name}"),
                        format!("unknown base parameter `{name}`"),
                        &format!(
                            "base parameters are {}",
                            BaseParam::ALL
                                .iter()
                                .map(|p| p.name())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    ));
                };
                let (lo, hi) = if param == BaseParam::K1Scale {
                    (0.2, 5.0)
                } else {
                    (0.0, f64::INFINITY)
                };
                let mut p = parse_param(
                    text,
                    file,
                    &format!("params.{name}"),
                    name,
                    param.unit(),
                    val,
                    lo,
                    hi,
                    true,
                )?;
                p.role = Role::Base(param);
                base.push(p);
            }
        } else {
            base = Model::baseline(ds)?.base;
        }
        let mut effects_out: Vec<EffectUse> = Vec::new();
        if let Some(v) = doc.get("effect") {
            let arr = v.as_array().ok_or_else(|| {
                err(
                    "effect",
                    "must be an array of tables".into(),
                    "write [[effect]] tables",
                )
            })?;
            for (i, e) in arr.iter().enumerate() {
                let path = format!("effect.{i}");
                let t = e
                    .as_table()
                    .ok_or_else(|| err(&path, "must be a table".into(), "write [[effect]]"))?;
                let name = t.get("name").and_then(|n| n.as_str()).ok_or_else(|| {
                    err(
                        &path,
                        "an [[effect]] needs name = \"...\"".into(),
                        &format!("registered effects: {}", effects::names().join(", ")),
                    )
                })?;
                let effect = effects::find(name).ok_or_else(|| {
                    err(
                        &format!("{path}.name"),
                        format!("unknown effect `{name}`"),
                        &format!("registered effects: {}", effects::names().join(", ")),
                    )
                })?;
                let given = t
                    .get("params")
                    .and_then(|p| p.as_table())
                    .cloned()
                    .unwrap_or_default();
                for k in given.keys() {
                    if !effect.params().iter().any(|p| p.name == k) {
                        return Err(err(
                            &format!("{path}.params.{k}"),
                            format!("effect `{name}` has no parameter `{k}`"),
                            &format!(
                                "its parameters: {}",
                                effect
                                    .params()
                                    .iter()
                                    .map(|p| p.name)
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        ));
                    }
                }
                let mut ps = Vec::new();
                for spec in effect.params() {
                    let p = match given.get(spec.name) {
                        Some(val) => {
                            let mut p = parse_param(
                                text,
                                file,
                                &format!("{path}.params.{}", spec.name),
                                spec.name,
                                spec.unit,
                                val,
                                spec.lower,
                                spec.upper,
                                false,
                            )?;
                            p.log_scale = spec.log_scale;
                            p
                        }
                        None => ParamDef {
                            name: spec.name.into(),
                            unit: spec.unit.into(),
                            value: spec.default,
                            run_values: None,
                            lower: spec.lower,
                            upper: spec.upper,
                            log_scale: spec.log_scale,
                            fit: spec.fitted,
                            per_run: false,
                            role: Role::Effect,
                        },
                    };
                    ps.push(p);
                }
                let shape = parse_shape(text, file, &path, effect, t)?;
                let at = parse_at(text, file, &path, effect, t, ds)?;
                for k in t.keys() {
                    if !["name", "params", "shape", "joints", "links"].contains(&k.as_str()) {
                        return Err(err(
                            &format!("{path}.{k}"),
                            format!("unknown key `{k}` in an [[effect]]"),
                            "an [[effect]] holds name, joints or links (arms), [effect.params.NAME] and [effect.shape] (docs/models.md)",
                        ));
                    }
                }
                // The same effect twice: on disjoint joints or links only (its values per
                // joint or per link).
                if let Some((j, on)) = at_overlap(&effects_out, effect, at.as_deref()) {
                    return Err(err(
                        &path,
                        format!("effect `{name}` is given twice on {on} (also [[effect]] {j})"),
                        &format!(
                            "give an effect once, or once per {} with disjoint `{}` lists",
                            at_unit(effect),
                            at_key(effect)
                        ),
                    ));
                }
                effects_out.push(EffectUse {
                    effect,
                    params: ps,
                    shape: None,
                    at,
                });
                if let Some(sh) = shape {
                    let last = effects_out.len() - 1;
                    let m = Model {
                        rope: String::new(),
                        law_kind,
                        law: law.clone(),
                        base: Vec::new(),
                        effects: std::mem::take(&mut effects_out),
                    };
                    effects_out = m.with_shape(last, sh).effects;
                }
            }
        }
        let m = Model {
            rope,
            law_kind,
            law,
            base,
            effects: effects_out,
        };
        m.law_for_run(0)
            .map_err(|e| err("effect", e.to_string(), "correct the parameter values"))?;
        Ok(m)
    }
}

/// What one name of `effect`'s [`EffectUse::at`] is: a `link` for an effect on a
/// link's bending, a `joint` for every other.
pub fn at_unit(effect: &'static dyn Effect) -> &'static str {
    if effects::bends_links(effect) {
        "link"
    } else {
        "joint"
    }
}

/// The model-file key that restricts `effect` on an arm ([`EffectUse::at`]): `links`
/// for an effect on a link's bending, `joints` for every other.
pub fn at_key(effect: &'static dyn Effect) -> &'static str {
    if at_unit(effect) == "link" {
        "links"
    } else {
        "joints"
    }
}

/// Why `names` cannot restrict `effect` on `ds` (message, fix), if it cannot: only on
/// arm datasets; an effect on a link's bending on flexible links of the dataset's arm
/// scenario, an effect at joints, motors, pairs or rope laws on joints the arm drives
/// (not an effect on the payload or a sensor); a non-empty list, each name once.
pub fn at_problem(
    effect: &'static dyn Effect,
    names: &[String],
    ds: &Dataset,
) -> Option<(String, String)> {
    let key = at_key(effect);
    let DatasetKind::ArmMoves(am) = &ds.kind else {
        return Some((
            format!("`{key}` applies to arm datasets (arm_moves) only"),
            format!("remove `{key}`: the rig has one joint and no flexible link"),
        ));
    };
    let bends = key == "links";
    if !bends && matches!(effect.site(), Site::Link | Site::Sensor) {
        return Some((
            format!(
                "effect `{}` acts on {}, not at joints",
                effect.name(),
                if effect.site() == Site::Link {
                    "the payload"
                } else {
                    "sensor channels"
                }
            ),
            "remove `joints` from this effect".into(),
        ));
    }
    let (known, example) = if bends {
        (&am.flex_links, "link2")
    } else {
        (&am.joints, "j2")
    };
    let listed = if known.is_empty() {
        "none".to_string()
    } else {
        known.join(", ")
    };
    if names.is_empty() {
        return Some((
            format!("must be a non-empty list of {key}"),
            format!("write {key} = [\"{example}\"] with names of: {listed}"),
        ));
    }
    for (i, n) in names.iter().enumerate() {
        if !known.contains(n) {
            return Some(if bends {
                (
                    format!("link `{n}` is not a flexible link of the dataset's arm scenario ([[flex]])"),
                    format!("use its flexible links: {listed}"),
                )
            } else {
                (
                    format!("joint `{n}` is not driven by the dataset's arm"),
                    format!("use joints the arm drives: {listed}"),
                )
            });
        }
        if names[..i].contains(n) {
            return Some((format!("`{n}` is listed twice"), "list each once".into()));
        }
    }
    None
}

/// Where `effect` at `at` (`None`: everywhere) overlaps a use of the same effect among
/// `uses`: that use's index and the joint or link (or "every joint" / "every link").
pub fn at_overlap(
    uses: &[EffectUse],
    effect: &'static dyn Effect,
    at: Option<&[String]>,
) -> Option<(usize, String)> {
    uses.iter().enumerate().find_map(|(j, other)| {
        if !effects::same(other.effect, effect) {
            return None;
        }
        match (other.at.as_deref(), at) {
            (Some(a), Some(b)) => a.iter().find(|x| b.contains(x)).map(|x| (j, x.clone())),
            _ => Some((j, format!("every {}", at_unit(effect)))),
        }
    })
}

/// The `joints` or `links` list ([`at_key`]) of effect `effect` at `path` in a model
/// file, if any ([`at_problem`]); the other key is refused.
fn parse_at(
    text: &str,
    file: &str,
    path: &str,
    effect: &'static dyn Effect,
    t: &toml::Table,
    ds: &Dataset,
) -> Result<Option<Vec<String>>, ModelError> {
    let key = at_key(effect);
    let other = if key == "links" { "joints" } else { "links" };
    if t.contains_key(other) {
        let field = format!("{path}.{other}");
        let (msg, fix) = if key == "links" {
            (
                format!(
                    "effect `{}` acts on flexible links, not at joints",
                    effect.name()
                ),
                "write links = [\"link2\"] with links of the scenario's [[flex]]",
            )
        } else {
            (
                format!(
                    "effect `{}` does not act on a link's bending",
                    effect.name()
                ),
                "write joints = [\"j2\"] with joints the arm drives, or remove `links`",
            )
        };
        return Err(ModelError::File(field_error(text, file, &field, msg, fix)));
    }
    let Some(v) = t.get(key) else {
        return Ok(None);
    };
    let field = format!("{path}.{key}");
    let err = |msg: String, fix: &str| ModelError::File(field_error(text, file, &field, msg, fix));
    let names: Vec<String> = v
        .as_array()
        .and_then(|a| {
            a.iter()
                .map(|x| x.as_str().map(str::to_string))
                .collect::<Option<Vec<_>>>()
        })
        .ok_or_else(|| {
            err(
                "must be a list of names".to_string(),
                &format!(
                    "write {key} = [\"{}\"]",
                    if key == "links" { "link2" } else { "j2" }
                ),
            )
        })?;
    match at_problem(effect, &names, ds) {
        Some((msg, fix)) => Err(err(msg, &fix)),
        None => Ok(Some(names)),
    }
}

/// The `[effect.shape]` table of effect `effect` at `path` in a model file, if any
/// (format: [`ShapeUse::to_toml`]).
fn parse_shape(
    text: &str,
    file: &str,
    path: &str,
    effect: &'static dyn Effect,
    t: &toml::Table,
) -> Result<Option<ShapeUse>, ModelError> {
    let Some(v) = t.get("shape") else {
        return Ok(None);
    };
    let field = format!("{path}.shape");
    let err = |field: &str, msg: String, fix: String| {
        ModelError::File(field_error(text, file, field, msg, &fix))
    };
    let Some(shape) = effect.shape() else {
        let with: Vec<&str> = effects::REGISTRY
            .iter()
            .filter(|e| e.shape().is_some())
            .map(|e| e.name())
            .collect();
        return Err(err(
            &field,
            format!("effect `{}` has no shape-free form", effect.name()),
            format!(
                "remove [effect.shape]; effects with one: {}",
                with.join(", ")
            ),
        ));
    };
    let (arg, val) = (shape.argument.name(), shape.value);
    let example = format!(
        "write [effect.shape] with {arg} = [0, ...] (knots from 0, increasing, 2 to {} of them), {val} = [...] (one value per knot) and fit = true or false",
        longreach_rope::MAX_KNOTS
    );
    let st = v
        .as_table()
        .ok_or_else(|| err(&field, "must be a table".into(), example.clone()))?;
    for k in st.keys() {
        if ![arg, val, "fit"].contains(&k.as_str()) {
            return Err(err(
                &format!("{field}.{k}"),
                format!("unknown key `{k}`"),
                example.clone(),
            ));
        }
    }
    let list = |key: &str| -> Result<Vec<f64>, ModelError> {
        let f = format!("{field}.{key}");
        let a = st
            .get(key)
            .and_then(|v| v.as_array())
            .ok_or_else(|| err(&f, format!("needs {key} = [numbers]"), example.clone()))?;
        a.iter()
            .map(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(|| err(&f, "must be a list of numbers".into(), example.clone()))
    };
    let knots = list(arg)?;
    let values = list(val)?;
    if knots.len() != values.len() {
        return Err(err(
            &format!("{field}.{val}"),
            format!("{} values for {} knots", values.len(), knots.len()),
            "give one value per knot".into(),
        ));
    }
    if let (Some(z), Some(&y0)) = (shape.value_at_zero, values.first()) {
        if (y0 - z).abs() > 1e-9 * z.abs().max(1.0) {
            return Err(err(
                &format!("{field}.{val}"),
                format!("the first value is {y0}, but this shape is {z} at {arg} = 0"),
                format!("start the values with {z} (another parameter holds the scale)"),
            ));
        }
    }
    let fit = match st.get("fit") {
        None => false,
        Some(v) => v.as_bool().ok_or_else(|| {
            err(
                &format!("{field}.fit"),
                "must be true or false".into(),
                example.clone(),
            )
        })?,
    };
    ShapeUse::new(effect, shape, &knots, &values, fit)
        .map(Some)
        .map_err(|e| err(&field, e.to_string(), example))
}

/// The four constants of the law (or k1 alone), fitted on a log scale within a decade.
fn law_constants(law: &RopeLaw) -> Vec<ParamDef> {
    let decade = |p: BaseParam, v: f64| ParamDef::base(p, v, v / 10.0, v * 10.0);
    let mut out = vec![decade(BaseParam::K1, law.k1_n)];
    if let Some(c2) = law.c2_n_s {
        out.push(decade(BaseParam::C2, c2));
    }
    if let Some(k) = law.kelvin.first() {
        out.push(decade(BaseParam::K3, k.k_n));
        out.push(decade(BaseParam::C3, k.c_n_s));
    }
    out
}

fn parse_param(
    text: &str,
    file: &str,
    path: &str,
    name: &str,
    unit: &str,
    val: &toml::Value,
    lower: f64,
    upper: f64,
    log_scale: bool,
) -> Result<ParamDef, ModelError> {
    let err = |msg: String| {
        ModelError::File(field_error(
            text,
            file,
            path,
            msg,
            "give a number (known) or a table { value, fit, lower, upper, per_run }",
        ))
    };
    let num = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
    let mut p = ParamDef {
        name: name.into(),
        unit: unit.into(),
        value: f64::NAN,
        run_values: None,
        lower,
        upper,
        log_scale,
        fit: false,
        per_run: false,
        role: Role::Effect,
    };
    match val {
        toml::Value::Table(t) => {
            for k in t.keys() {
                // `interval_95`: written with fitted values, ignored when read
                if ![
                    "value",
                    "fit",
                    "lower",
                    "upper",
                    "per_run",
                    "run_values",
                    "interval_95",
                ]
                .contains(&k.as_str())
                {
                    return Err(err(format!("unknown key `{k}`")));
                }
            }
            p.value = t
                .get("value")
                .and_then(num)
                .ok_or_else(|| err("needs value = <number>".into()))?;
            p.fit = t.get("fit").and_then(|v| v.as_bool()).unwrap_or(false);
            p.per_run = t.get("per_run").and_then(|v| v.as_bool()).unwrap_or(false);
            if let Some(v) = t.get("lower") {
                p.lower = num(v).ok_or_else(|| err("lower must be a number".into()))?;
            }
            if let Some(v) = t.get("upper") {
                p.upper = num(v).ok_or_else(|| err("upper must be a number".into()))?;
            }
            if let Some(v) = t.get("run_values") {
                let a = v
                    .as_array()
                    .ok_or_else(|| err("run_values must be a list of numbers".into()))?;
                let vals: Option<Vec<f64>> = a.iter().map(num).collect();
                p.run_values =
                    Some(vals.ok_or_else(|| err("run_values must be a list of numbers".into()))?);
            }
        }
        v => p.value = num(v).ok_or_else(|| err("must be a number or a table".into()))?,
    }
    if !(p.value.is_finite() && p.lower <= p.value && p.value <= p.upper && p.lower < p.upper) {
        return Err(err(format!(
            "value {} outside its bounds [{}, {}] {unit}",
            p.value, p.lower, p.upper
        )));
    }
    if p.log_scale && p.lower <= 0.0 && p.fit {
        p.lower = p.value * 1e-3;
    }
    Ok(p)
}

/// Who owns a parameter slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Owner {
    /// A base parameter.
    Base,
    /// The parameters of effect number `n`.
    Effect(usize),
    /// The shape-free table of effect number `n`.
    Shape(usize),
}

/// One fitted value: parameter `index` of `owner`, for run `run` (per-run) or all runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    /// Owner.
    pub owner: Owner,
    /// Parameter index within the owner.
    pub index: usize,
    /// Run of a per-run parameter.
    pub run: Option<usize>,
}
