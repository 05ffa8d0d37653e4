//! URDF file -> validated [`ArmSpec`].
//!
//! Two passes over the text:
//! 1. a quick-xml scan that checks the XML is well formed (error with line and
//!    column), records the line of every `<link>` and `<joint>` for messages, and
//!    lists every element the simulator does not use (urdf-rs drops some of them
//!    silently: `<transmission>`, `<gazebo>`, unknown tags) as a warning;
//! 2. urdf-rs for the content, then the tree is checked (missing links, two
//!    parents, loops, several roots), fixed joints are merged into their parent body
//!    (mass, centre of mass, inertia by the parallel-axis theorem; visuals and frames
//!    kept), and the result is validated ([`ArmSpec::validate`]).
//!
//! Supported: revolute and continuous joints, fixed joints (merged). A floating or
//! planar joint from the root link is treated as fixed (base bolted to the world)
//! with a warning; anywhere else, and prismatic/spherical joints, are errors.

use crate::spec::{
    check_moving_inertial, satisfies_triangle_inequality, ArmSpec, Element, Frame, Geometry,
    Inertial, JointKind, JointSpec, LinkSpec, Visual, STANDARD_GRAVITY_M_S2,
};
use nalgebra::{Isometry3, Matrix3, Translation3, Unit, UnitQuaternion, Vector3};
use quick_xml::events::{BytesStart, Event};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::Path;

/// Why a URDF could not be turned into an [`ArmSpec`].
#[derive(Debug, thiserror::Error)]
pub enum UrdfError {
    /// The file could not be read.
    #[error("{path}: cannot read the URDF file: {source}")]
    Io {
        /// File path.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The text is not well-formed XML.
    #[error("{path}:{line}:{column}: malformed XML: {message}")]
    Xml {
        /// File path (or label).
        path: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// Parser message.
        message: String,
    },
    /// Well-formed XML that urdf-rs could not read as a URDF.
    #[error("{path}: not a readable URDF: {message} (every <joint> needs a name, a type, <parent link=..> and <child link=..>; a <limit> needs effort and velocity; every <inertial> needs <mass> and <inertia>)")]
    Parse {
        /// File path (or label).
        path: String,
        /// urdf-rs message.
        message: String,
    },
    /// A URDF element is inconsistent or physically invalid.
    #[error("{}: {element}: {reason}", location(path, *line))]
    Invalid {
        /// File path (or label).
        path: String,
        /// 1-based line of the element, when known.
        line: Option<usize>,
        /// The offending link or joint.
        element: Element,
        /// What is wrong and what to do.
        reason: String,
    },
}

fn location(path: &str, line: Option<usize>) -> String {
    match line {
        Some(l) => format!("{path}:{l}"),
        None => path.to_string(),
    }
}

/// Reads and compiles a URDF file. Warnings (content not simulated) are in
/// [`ArmSpec::warnings`].
pub fn load_urdf(path: impl AsRef<Path>) -> Result<ArmSpec, UrdfError> {
    let path = path.as_ref();
    let label = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| UrdfError::Io {
        path: label.clone(),
        source,
    })?;
    parse_urdf(&text, &label)
}

/// Compiles URDF text; `source` names it in messages (e.g. a file path).
pub fn parse_urdf(xml: &str, source: &str) -> Result<ArmSpec, UrdfError> {
    let scan = scan_xml(xml, source)?;
    let robot = urdf_rs::read_from_string(xml).map_err(|e| UrdfError::Parse {
        path: source.to_string(),
        message: e.to_string(),
    })?;
    Builder {
        robot: &robot,
        scan: &scan,
        path: source,
    }
    .build()
}

// ---------------------------------------------------------------------------------
// Pass 1: XML scan.

#[derive(Debug, Default)]
struct XmlScan {
    /// Lines of each `<link name=..>` (several if duplicated).
    link_lines: BTreeMap<String, Vec<usize>>,
    /// Lines of each `<joint name=..>`.
    joint_lines: BTreeMap<String, Vec<usize>>,
    /// Joints that have a `<limit>` child.
    joints_with_limit: BTreeSet<String>,
    /// Content not used by the simulator.
    warnings: Vec<String>,
}

impl XmlScan {
    fn link_line(&self, name: &str) -> Option<usize> {
        self.link_lines.get(name).and_then(|v| v.first().copied())
    }
    fn joint_line(&self, name: &str) -> Option<usize> {
        self.joint_lines.get(name).and_then(|v| v.first().copied())
    }
}

struct LineIndex {
    starts: Vec<usize>,
}

impl LineIndex {
    fn new(text: &str) -> Self {
        let mut starts = vec![0];
        starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Self { starts }
    }
    /// 1-based (line, column) of a byte offset.
    fn line_col(&self, offset: usize) -> (usize, usize) {
        let line = self.starts.partition_point(|&s| s <= offset);
        let col = offset - self.starts[line.saturating_sub(1)] + 1;
        (line.max(1), col)
    }
}

fn name_attr(e: &BytesStart<'_>) -> Option<String> {
    e.try_get_attribute("name")
        .ok()
        .flatten()
        .and_then(|a| a.unescape_value().ok().map(|v| v.into_owned()))
}

struct Open {
    tag: String,
    name: Option<String>,
    line: usize,
    collisions: usize,
}

fn scan_xml(xml: &str, path: &str) -> Result<XmlScan, UrdfError> {
    let lines = LineIndex::new(xml);
    let mut reader = quick_xml::Reader::from_str(xml);
    reader.config_mut().trim_text(true);
    let mut scan = XmlScan::default();
    let mut stack: Vec<Open> = Vec::new();
    let mut saw_root = false;
    let xml_err = |offset: u64, message: String| {
        let (line, column) = lines.line_col(usize::try_from(offset).unwrap_or(usize::MAX));
        UrdfError::Xml {
            path: path.to_string(),
            line,
            column,
            message,
        }
    };
    loop {
        let before = usize::try_from(reader.buffer_position()).unwrap_or(usize::MAX);
        let event = reader
            .read_event()
            .map_err(|e| xml_err(reader.error_position(), e.to_string()))?;
        let (start, is_empty) = match &event {
            Event::Start(e) => (Some(e.clone()), false),
            Event::Empty(e) => (Some(e.clone()), true),
            Event::End(_) => {
                if let Some(closed) = stack.pop() {
                    finish_element(&closed, &stack, &mut scan);
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        let Some(e) = start else { continue };
        let tag = String::from_utf8_lossy(e.name().as_ref()).into_owned();
        let offset = xml
            .get(before.min(xml.len())..)
            .and_then(|s| s.find('<'))
            .map_or(before, |i| before + i);
        let line = lines.line_col(offset).0;
        let name = name_attr(&e);
        match stack.len() {
            0 => {
                if tag != "robot" || saw_root {
                    return Err(xml_err(
                        offset as u64,
                        format!("expected a single <robot> root element, found <{tag}>"),
                    ));
                }
                saw_root = true;
            }
            1 => match tag.as_str() {
                "link" => {
                    if let Some(n) = &name {
                        scan.link_lines.entry(n.clone()).or_default().push(line);
                    }
                }
                "joint" => {
                    if let Some(n) = &name {
                        scan.joint_lines.entry(n.clone()).or_default().push(line);
                    }
                }
                "material" => {}
                "transmission" => scan.warnings.push(format!(
                    "line {line}: <transmission{}> ignored: rope transmissions are defined in longreach scenario files, not read from URDF",
                    named(&name)
                )),
                "gazebo" => scan.warnings.push(format!(
                    "line {line}: <gazebo{}> ignored: Gazebo-specific content is not simulated",
                    gazebo_ref(&e)
                )),
                other => scan.warnings.push(format!(
                    "line {line}: <{other}{}> ignored: not a URDF element this simulator reads",
                    named(&name)
                )),
            },
            2 => {
                let parent = &mut stack[1];
                let owner = parent.name.clone().unwrap_or_default();
                match (parent.tag.as_str(), tag.as_str()) {
                    ("link", "inertial" | "visual") => {}
                    ("link", "collision") => parent.collisions += 1,
                    ("joint", "origin" | "parent" | "child" | "axis" | "dynamics") => {}
                    ("joint", "limit") => {
                        scan.joints_with_limit.insert(owner);
                    }
                    ("joint", "mimic") => scan.warnings.push(format!(
                        "line {line}: joint '{owner}': <mimic> ignored: the joint moves independently"
                    )),
                    ("joint", "calibration" | "safety_controller") => scan.warnings.push(format!(
                        "line {line}: joint '{owner}': <{tag}> ignored (not simulated)"
                    )),
                    ("material", _) => {}
                    (ptag, _) if ptag == "link" || ptag == "joint" => scan.warnings.push(format!(
                        "line {line}: {ptag} '{owner}': <{tag}> ignored: not a URDF element this simulator reads"
                    )),
                    _ => {}
                }
            }
            _ => {}
        }
        let open = Open {
            tag,
            name,
            line,
            collisions: 0,
        };
        if is_empty {
            finish_element(&open, &stack, &mut scan);
        } else {
            stack.push(open);
        }
    }
    if let Some(open) = stack.last() {
        return Err(UrdfError::Xml {
            path: path.to_string(),
            line: open.line,
            column: 1,
            message: format!("<{}> is never closed", open.tag),
        });
    }
    if !saw_root {
        return Err(UrdfError::Xml {
            path: path.to_string(),
            line: 1,
            column: 1,
            message: "no <robot> element".into(),
        });
    }
    Ok(scan)
}

fn finish_element(closed: &Open, stack: &[Open], scan: &mut XmlScan) {
    if stack.len() == 1 && closed.tag == "link" && closed.collisions > 0 {
        scan.warnings.push(format!(
            "line {}: link '{}': {} <collision> element(s) ignored: contacts are not simulated",
            closed.line,
            closed.name.as_deref().unwrap_or(""),
            closed.collisions
        ));
    }
}

fn named(name: &Option<String>) -> String {
    name.as_ref()
        .map(|n| format!(" name=\"{n}\""))
        .unwrap_or_default()
}

fn gazebo_ref(e: &BytesStart<'_>) -> String {
    e.try_get_attribute("reference")
        .ok()
        .flatten()
        .and_then(|a| a.unescape_value().ok().map(|v| v.into_owned()))
        .map(|r| format!(" reference=\"{r}\""))
        .unwrap_or_default()
}

// ---------------------------------------------------------------------------------
// Pass 2: content.

fn pose_to_iso(p: &urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = p.xyz.0;
    let [r, pi, ya] = p.rpy.0;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(r, pi, ya),
    )
}

fn iso_is_finite(iso: &Isometry3<f64>) -> bool {
    iso.translation
        .vector
        .iter()
        .chain(iso.rotation.coords.iter())
        .all(|x| x.is_finite())
}

/// How a URDF joint is treated.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Treat {
    Moving(JointKind),
    Fixed,
}

struct Builder<'a> {
    robot: &'a urdf_rs::Robot,
    scan: &'a XmlScan,
    path: &'a str,
}

impl Builder<'_> {
    fn link_err(&self, link: &str, reason: String) -> UrdfError {
        UrdfError::Invalid {
            path: self.path.to_string(),
            line: self.scan.link_line(link),
            element: Element::Link(link.to_string()),
            reason,
        }
    }

    fn joint_err(&self, joint: &str, reason: String) -> UrdfError {
        UrdfError::Invalid {
            path: self.path.to_string(),
            line: self.scan.joint_line(joint),
            element: Element::Joint(joint.to_string()),
            reason,
        }
    }

    fn build(&self) -> Result<ArmSpec, UrdfError> {
        let robot = self.robot;
        let mut warnings = self.scan.warnings.clone();

        // Names.
        let mut link_index: BTreeMap<&str, usize> = BTreeMap::new();
        for (i, link) in robot.links.iter().enumerate() {
            if link_index.insert(link.name.as_str(), i).is_some() {
                let lines = self
                    .scan
                    .link_lines
                    .get(&link.name)
                    .cloned()
                    .unwrap_or_default();
                return Err(UrdfError::Invalid {
                    path: self.path.to_string(),
                    line: lines.get(1).copied(),
                    element: Element::Link(link.name.clone()),
                    reason: format!(
                        "defined more than once (lines {lines:?}): link names must be unique"
                    ),
                });
            }
        }
        if robot.links.is_empty() {
            return Err(UrdfError::Invalid {
                path: self.path.to_string(),
                line: None,
                element: Element::Arm,
                reason: "no <link> element".into(),
            });
        }
        let mut seen_joints = BTreeSet::new();
        for joint in &robot.joints {
            if !seen_joints.insert(joint.name.as_str()) {
                let lines = self
                    .scan
                    .joint_lines
                    .get(&joint.name)
                    .cloned()
                    .unwrap_or_default();
                return Err(UrdfError::Invalid {
                    path: self.path.to_string(),
                    line: lines.get(1).copied(),
                    element: Element::Joint(joint.name.clone()),
                    reason: format!(
                        "defined more than once (lines {lines:?}): joint names must be unique"
                    ),
                });
            }
        }

        // Parent/child links exist; each link has at most one parent joint.
        let nl = robot.links.len();
        let mut parent_joint: Vec<Option<usize>> = vec![None; nl];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); nl];
        let mut jparent = Vec::with_capacity(robot.joints.len());
        let mut jchild = Vec::with_capacity(robot.joints.len());
        for (ji, joint) in robot.joints.iter().enumerate() {
            let find = |role: &str, name: &str| {
                link_index.get(name).copied().ok_or_else(|| {
                    self.joint_err(
                        &joint.name,
                        format!("{role} link '{name}' is not defined: add <link name=\"{name}\"> or fix the name"),
                    )
                })
            };
            let p = find("parent", &joint.parent.link)?;
            let c = find("child", &joint.child.link)?;
            if p == c {
                return Err(self.joint_err(
                    &joint.name,
                    format!("parent and child are the same link '{}'", joint.parent.link),
                ));
            }
            if let Some(other) = parent_joint[c] {
                return Err(self.link_err(
                    &joint.child.link,
                    format!(
                        "is the child of two joints, '{}' and '{}': a URDF must be a tree (closed kinematic loops are not supported)",
                        robot.joints[other].name, joint.name
                    ),
                ));
            }
            parent_joint[c] = Some(ji);
            children[p].push(ji);
            jparent.push(p);
            jchild.push(c);
        }

        // Loops: walking up from any link must end at a root.
        for start in 0..nl {
            let mut on_path = vec![false; nl];
            let mut path_joints = Vec::new();
            let mut l = start;
            while let Some(ji) = parent_joint[l] {
                if on_path[l] {
                    // Keep only the loop part.
                    let loop_start = path_joints
                        .iter()
                        .position(|&j| jchild[j] == l)
                        .unwrap_or(0);
                    let names: Vec<&str> = path_joints[loop_start..]
                        .iter()
                        .rev()
                        .map(|&j: &usize| robot.joints[j].name.as_str())
                        .collect();
                    return Err(self.joint_err(
                        &robot.joints[ji].name,
                        format!(
                            "kinematic loop (cycle) through joints {}: a URDF must be a tree with one root link",
                            names.join(" -> ")
                        ),
                    ));
                }
                on_path[l] = true;
                path_joints.push(ji);
                l = jparent[ji];
            }
        }
        let roots: Vec<usize> = (0..nl).filter(|&l| parent_joint[l].is_none()).collect();
        let root = match roots.as_slice() {
            [r] => *r,
            [] => unreachable_cycle(self.path)?,
            [first, rest @ ..] => {
                let others: Vec<&str> =
                    rest.iter().map(|&l| robot.links[l].name.as_str()).collect();
                return Err(self.link_err(
                    &robot.links[rest[0]].name,
                    format!(
                        "not connected to the tree rooted at '{}' (other unconnected links: {}): connect it with a joint or remove it",
                        robot.links[*first].name,
                        others.join(", ")
                    ),
                ));
            }
        };

        // Joint treatment.
        let mut treat = Vec::with_capacity(robot.joints.len());
        for (ji, joint) in robot.joints.iter().enumerate() {
            use urdf_rs::JointType as T;
            let t = match joint.joint_type {
                T::Revolute => Treat::Moving(JointKind::Revolute),
                T::Continuous => Treat::Moving(JointKind::Continuous),
                T::Fixed => Treat::Fixed,
                T::Floating | T::Planar if jparent[ji] == root => {
                    warnings.push(format!(
                        "joint '{}' ({:?}) from the root link treated as fixed: the base is bolted to the world",
                        joint.name, joint.joint_type
                    ));
                    Treat::Fixed
                }
                T::Floating | T::Planar => {
                    return Err(self.joint_err(
                        &joint.name,
                        format!(
                            "{:?} joints are only accepted from the root link (treated as a fixed base); here it is mid-chain: use revolute, continuous or fixed",
                            joint.joint_type
                        ),
                    ))
                }
                T::Prismatic | T::Spherical => {
                    return Err(self.joint_err(
                        &joint.name,
                        format!(
                            "{:?} joints are not supported: only revolute, continuous and fixed joints",
                            joint.joint_type
                        ),
                    ))
                }
            };
            treat.push(t);
        }

        // Raw inertials, checked before merging.
        let mut raw_inertial = Vec::with_capacity(nl);
        for link in &robot.links {
            let inr = &link.inertial;
            let m = inr.mass.value;
            if !m.is_finite() || m < 0.0 {
                return Err(self.link_err(
                    &link.name,
                    format!("mass {m} kg is negative or not finite: masses must be >= 0"),
                ));
            }
            let i = &inr.inertia;
            let tensor = Matrix3::new(
                i.ixx, i.ixy, i.ixz, //
                i.ixy, i.iyy, i.iyz, //
                i.ixz, i.iyz, i.izz,
            );
            let frame = pose_to_iso(&inr.origin);
            if !tensor.iter().all(|x| x.is_finite()) || !iso_is_finite(&frame) {
                return Err(self.link_err(&link.name, "<inertial> has non-finite numbers".into()));
            }
            // The tensor is given in the inertial frame (origin rpy); rotate to the link frame.
            let local = Inertial {
                mass_kg: m,
                com_m: Vector3::zeros(),
                inertia_kg_m2: tensor,
            };
            let inertial = local.transformed(&frame);
            if m > 0.0 || tensor.iter().any(|&x| x != 0.0) {
                let ev = inertial.principal_moments_kg_m2();
                if ev[0] < -1e-12 * ev[2].abs().max(1e-300) {
                    return Err(self.link_err(
                        &link.name,
                        format!(
                            "inertia tensor has a negative principal moment ({:.6e}, {:.6e}, {:.6e} kg*m^2): not a physical body; check ixx..izz and the signs of ixy, ixz, iyz",
                            ev[0], ev[1], ev[2]
                        ),
                    ));
                }
                if !satisfies_triangle_inequality(&inertial) {
                    warnings.push(format!(
                        "link '{}': principal moments {:.6e}, {:.6e}, {:.6e} kg*m^2 violate the triangle inequality (no physical body has them); simulated as given",
                        link.name, ev[0], ev[1], ev[2]
                    ));
                }
            }
            raw_inertial.push(inertial);
        }

        // Walk the tree breadth-first from the root: bodies get indices parents-first.
        // body_of[l] = (body index, body_from_link, depth below the body's own link).
        let mut body_of: Vec<Option<(usize, Isometry3<f64>, usize)>> = vec![None; nl];
        body_of[root] = Some((0, Isometry3::identity(), 0));
        let mut body_link: Vec<usize> = vec![root];
        let mut joint_specs: Vec<JointSpec> = Vec::new();
        let mut queue = VecDeque::from([root]);
        let mut visit_order = Vec::with_capacity(nl);
        while let Some(l) = queue.pop_front() {
            visit_order.push(l);
            let Some((body, body_from_l, depth)) = body_of[l] else {
                continue;
            };
            for &ji in &children[l] {
                let joint = &robot.joints[ji];
                let c = jchild[ji];
                let origin = pose_to_iso(&joint.origin);
                if !iso_is_finite(&origin) {
                    return Err(
                        self.joint_err(&joint.name, "<origin> has non-finite numbers".into())
                    );
                }
                let body_from_joint = body_from_l * origin;
                match treat[ji] {
                    Treat::Fixed => {
                        body_of[c] = Some((body, body_from_joint, depth + 1));
                    }
                    Treat::Moving(kind) => {
                        let child_body = body_link.len();
                        body_link.push(c);
                        body_of[c] = Some((child_body, Isometry3::identity(), 0));
                        joint_specs.push(self.joint_spec(
                            joint,
                            kind,
                            body,
                            child_body,
                            body_from_joint,
                            &mut warnings,
                        )?);
                    }
                }
                queue.push_back(c);
            }
        }

        // Bodies: merge inertials, visuals and frames.
        let materials: BTreeMap<&str, [f64; 4]> = robot
            .materials
            .iter()
            .filter_map(|m| m.color.as_ref().map(|c| (m.name.as_str(), c.rgba.0)))
            .collect();
        let mut links: Vec<LinkSpec> = body_link
            .iter()
            .map(|&l| LinkSpec {
                name: robot.links[l].name.clone(),
                merged_links: Vec::new(),
                inertial: Inertial::zero(),
                visuals: Vec::new(),
            })
            .collect();
        let mut frames = Vec::with_capacity(nl);
        let mut frame_depth = Vec::with_capacity(nl);
        for &l in &visit_order {
            let Some((body, body_from_l, depth)) = body_of[l] else {
                continue;
            };
            let link = &robot.links[l];
            let spec = &mut links[body];
            if body_link[body] != l {
                spec.merged_links.push(link.name.clone());
            }
            spec.inertial = spec
                .inertial
                .combined(&raw_inertial[l].transformed(&body_from_l));
            for v in &link.visual {
                let link_from_visual = body_from_l * pose_to_iso(&v.origin);
                let rgba = v.material.as_ref().and_then(|m| {
                    m.color
                        .as_ref()
                        .map(|c| c.rgba.0)
                        .or_else(|| materials.get(m.name.as_str()).copied())
                });
                spec.visuals.push(Visual {
                    source_link: link.name.clone(),
                    link_from_visual,
                    geometry: geometry(&v.geometry),
                    rgba,
                });
            }
            frames.push(Frame {
                name: link.name.clone(),
                link: body,
                link_from_frame: body_from_l,
            });
            frame_depth.push(depth);
        }
        for (b, spec) in links.iter().enumerate().skip(1) {
            check_moving_inertial(&spec.name, &spec.inertial).map_err(|reason| {
                let merged = if spec.merged_links.is_empty() {
                    String::new()
                } else {
                    format!(" (with merged links {})", spec.merged_links.join(", "))
                };
                self.link_err(&spec.name, format!("moving body {b}{merged}: {reason}"))
            })?;
        }

        // Tip: a frame named "tip", else the deepest frame on the last body.
        let last = links.len() - 1;
        let tip = frames
            .iter()
            .position(|f| f.name == "tip")
            .or_else(|| {
                frames
                    .iter()
                    .enumerate()
                    .filter(|(_, f)| f.link == last)
                    .max_by_key(|(i, _)| (frame_depth[*i], *i))
                    .map(|(i, _)| i)
            })
            .map(|i| frames[i].clone())
            .unwrap_or_else(|| Frame {
                name: links[last].name.clone(),
                link: last,
                link_from_frame: Isometry3::identity(),
            });

        let spec = ArmSpec {
            name: robot.name.clone(),
            source: self.path.to_string(),
            links,
            joints: joint_specs,
            frames,
            tip,
            gravity_m_s2: Vector3::new(0.0, 0.0, -STANDARD_GRAVITY_M_S2),
            warnings,
        };
        spec.validate().map_err(|e| {
            let line = match &e.element {
                Element::Link(n) => self.scan.link_line(n),
                Element::Joint(n) => self.scan.joint_line(n),
                Element::Arm => None,
            };
            UrdfError::Invalid {
                path: self.path.to_string(),
                line,
                element: e.element,
                reason: e.reason,
            }
        })?;
        Ok(spec)
    }

    fn joint_spec(
        &self,
        joint: &urdf_rs::Joint,
        kind: JointKind,
        parent_body: usize,
        child_body: usize,
        parent_from_joint: Isometry3<f64>,
        warnings: &mut Vec<String>,
    ) -> Result<JointSpec, UrdfError> {
        let a = Vector3::from(joint.axis.xyz.0);
        let norm = a.norm();
        if !norm.is_finite() || norm < 1e-12 {
            return Err(self.joint_err(
                &joint.name,
                format!(
                    "axis xyz=\"{} {} {}\" has zero (or non-finite) length: give the rotation axis, e.g. <axis xyz=\"0 1 0\"/>",
                    a.x, a.y, a.z
                ),
            ));
        }
        if (norm - 1.0).abs() > 1e-6 {
            warnings.push(format!(
                "joint '{}': axis length {norm} normalised to 1",
                joint.name
            ));
        }
        let axis = Unit::new_normalize(a);
        let lim = &joint.limit;
        let has_limit = self.scan.joints_with_limit.contains(&joint.name);
        let limits_rad = match kind {
            JointKind::Continuous => None,
            JointKind::Revolute if !has_limit => {
                warnings.push(format!(
                    "joint '{}': revolute without <limit>: simulated without position limits",
                    joint.name
                ));
                None
            }
            JointKind::Revolute => {
                let (lo, hi) = (lim.lower, lim.upper);
                if lo.is_infinite() && hi.is_infinite() && lo < hi {
                    None
                } else if lo.is_infinite() || hi.is_infinite() {
                    warnings.push(format!(
                        "joint '{}': one-sided limit [{lo}, {hi}] rad not supported: simulated without position limits",
                        joint.name
                    ));
                    None
                } else if lo >= hi {
                    return Err(self.joint_err(
                        &joint.name,
                        format!(
                            "limit lower = {lo} rad, upper = {hi} rad leaves no motion: need lower < upper (type=\"continuous\" for no limits, \"fixed\" for no motion)"
                        ),
                    ));
                } else {
                    Some((lo, hi))
                }
            }
        };
        let (effort, velocity) = if has_limit {
            (lim.effort, lim.velocity)
        } else {
            (f64::INFINITY, f64::INFINITY)
        };
        let (damping, friction) = joint
            .dynamics
            .as_ref()
            .map_or((0.0, 0.0), |d| (d.damping, d.friction));
        Ok(JointSpec {
            name: joint.name.clone(),
            kind,
            parent_link: parent_body,
            child_link: child_body,
            parent_from_joint,
            axis,
            limits_rad,
            effort_limit_n_m: effort,
            velocity_limit_rad_s: velocity,
            damping_n_m_s_per_rad: damping,
            friction_n_m: friction,
            armature_kg_m2: 0.0,
        })
    }
}

/// Every link having a parent joint implies a loop, which the loop check reports first.
fn unreachable_cycle(path: &str) -> Result<usize, UrdfError> {
    Err(UrdfError::Invalid {
        path: path.to_string(),
        line: None,
        element: Element::Arm,
        reason: "no root link (every link is some joint's child): the joints form a loop".into(),
    })
}

fn geometry(g: &urdf_rs::Geometry) -> Geometry {
    match g {
        urdf_rs::Geometry::Box { size } => Geometry::Box {
            size_m: Vector3::from(size.0),
        },
        urdf_rs::Geometry::Cylinder { radius, length } => Geometry::Cylinder {
            radius_m: *radius,
            length_m: *length,
        },
        urdf_rs::Geometry::Capsule { radius, length } => Geometry::Capsule {
            radius_m: *radius,
            length_m: *length,
        },
        urdf_rs::Geometry::Sphere { radius } => Geometry::Sphere { radius_m: *radius },
        urdf_rs::Geometry::Mesh { filename, scale } => Geometry::Mesh {
            filename: filename.clone(),
            scale: scale.map_or(Vector3::new(1.0, 1.0, 1.0), |s| Vector3::from(s.0)),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_index_maps_offsets() {
        let idx = LineIndex::new("ab\ncd\n\nef");
        assert_eq!(idx.line_col(0), (1, 1));
        assert_eq!(idx.line_col(3), (2, 1));
        assert_eq!(idx.line_col(4), (2, 2));
        assert_eq!(idx.line_col(7), (4, 1));
    }

    #[test]
    fn rpy_is_fixed_axis_roll_pitch_yaw() {
        // URDF: R = Rz(yaw) Ry(pitch) Rx(roll).
        let p = urdf_rs::Pose {
            xyz: urdf_rs::Vec3([0.0; 3]),
            rpy: urdf_rs::Vec3([0.3, -0.2, 1.1]),
        };
        let r = pose_to_iso(&p).rotation;
        let expected = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.1)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -0.2)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.3);
        assert!(r.angle_to(&expected) < 1e-14);
    }
}
