//! Per-link values of an effect on a link's bending (`link_flexibility` with
//! `links = [...]`): the model file, the plant (against a scenario whose link is given
//! its numbers directly), the written scenario, the errors, and the split per link.

use std::path::{Path, PathBuf};

use longreach_ident::model::Model;
use longreach_ident::plant::{plant_for, Channels};
use longreach_ident::synth::{arm_moves, arm_plan, ArmMove, ArmMovesOptions};
use longreach_ident::{Dataset, DatasetKind};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Every moving link of longreach5 the same thin CFRP tube (E I 2.3e5 N*m^2,
/// 1.39 kg/m), the link's housings riding on it.
const EVERY_LINK: &str = "\n[[flex]]\nlink = \"*\"\nyoungs_modulus_pa = 110e9\n\
    outer_diameter_m = 0.14\ninner_diameter_m = 0.136\ndensity_kg_m3 = 1600.0\n\
    damping_ratio = 0.02\n";

/// `flex_dyneema2_base_step.toml` with its `[[flex]]` entries replaced by `flex`,
/// written as `name` in `dir` (its URDF by absolute path).
fn flex_scenario(dir: &Path, name: &str, flex: &str) -> PathBuf {
    let shipped = root().join("scenarios/flex_dyneema2_base_step.toml");
    let mut doc: toml::Table = std::fs::read_to_string(shipped).unwrap().parse().unwrap();
    doc.remove("flex");
    doc.remove("flex_defaults");
    let urdf = root().join("robots/longreach5/longreach5.urdf");
    doc["arm"]
        .as_table_mut()
        .unwrap()
        .insert("urdf".into(), urdf.display().to_string().into());
    let path = dir.join(name);
    std::fs::write(&path, toml::to_string(&doc).unwrap() + flex).unwrap();
    path
}

/// Link 3 softer and more damped than the others, in a model file.
const LINK3: &str = "[[effect]]\nname = \"link_flexibility\"\nlinks = [\"link3\"]\n\
    [effect.params.ei_scale]\nvalue = 0.5\n[effect.params.damping_ratio]\nvalue = 0.03\n";

/// The largest difference between two simulations' channels, relative to each
/// channel's largest magnitude.
fn worst_relative(a: &Channels, b: &Channels) -> f64 {
    assert_eq!(a.0.len(), b.0.len());
    a.0.iter()
        .zip(&b.0)
        .map(|(x, y)| {
            let scale = x.values.iter().fold(1e-12, |m: f64, v| m.max(v.abs()));
            x.values
                .iter()
                .zip(&y.values)
                .map(|(u, v)| (u - v).abs() / scale)
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// `link_flexibility` restricted to one link acts on that link alone: the arm simulates
/// as a scenario that gives the link the scaled `E I` and the damping ratio itself,
/// differs from the arm without it, and the scenario `--write-scenario` writes (a copy
/// of the `"*"` entry for the link) simulates as the model; the model file keeps the
/// links, and every misuse of `links` / `joints` is refused with its place and fix.
#[test]
fn link_flexibility_takes_values_per_link() {
    let dir = tempfile::tempdir().unwrap();
    let star = flex_scenario(dir.path(), "star.toml", EVERY_LINK);
    let mut opt = ArmMovesOptions::new(star, 7);
    opt.duration_s = 1.0;
    opt.moves = vec![ArmMove {
        joint: "j2".into(),
        move_rad: 0.05,
        start_s: 0.2,
        payload_kg: None,
    }];
    let plan = arm_plan(&opt).unwrap();
    let DatasetKind::ArmMoves(am) = &plan.kind else {
        panic!("not an arm plan")
    };
    assert_eq!(
        am.flex_links,
        ["link1", "link2", "link3", "link4", "link5"],
        "the flexible links of `*`"
    );
    let truth = Model::from_toml(LINK3, "truth.toml", &plan).unwrap();
    assert_eq!(truth.effects[0].label(), "link_flexibility@link3");
    let names: Vec<String> = truth.named_values().into_iter().map(|(n, _)| n).collect();
    assert!(names.contains(&"ei_scale@link3".to_string()), "{names:?}");
    let back = Model::from_toml(&truth.to_toml(""), "back.toml", &plan).unwrap();
    assert_eq!(back.named_values(), truth.named_values());
    assert_eq!(back.effects[0].at, truth.effects[0].at);
    let data = dir.path().join("data");
    arm_moves(&truth, &plan, &opt)
        .unwrap()
        .write(&data, "link 3 softer")
        .unwrap();
    let ds = Dataset::load(&data).unwrap();
    let DatasetKind::ArmMoves(am) = &ds.kind else {
        panic!("not an arm dataset")
    };
    let sim = |ds: &Dataset, m: &Model| {
        plant_for(ds, 1)
            .simulate(&m.plant_params(0).unwrap(), 0)
            .unwrap()
    };
    let with = sim(&ds, &truth);

    // The same arm with link 3's numbers in its own [[flex]] entry (a link's own entry
    // wins over "*"): E I halved through E (exactly half), damping 0.03.
    let own = dir.path().join("own");
    am.write(&own, "link 3 given directly").unwrap();
    let link3 = EVERY_LINK
        .replace("\"*\"", "\"link3\"")
        .replace("110e9", "55e9")
        .replace("0.02", "0.03");
    std::fs::copy(
        flex_scenario(dir.path(), "own.toml", &format!("{EVERY_LINK}{link3}")),
        own.join(&am.scenario),
    )
    .unwrap();
    let direct = Dataset::load(&own).unwrap();
    let base = Model::baseline(&ds).unwrap();
    let worst = worst_relative(&with, &sim(&direct, &base));
    assert!(
        worst <= 1e-9,
        "per-link effect vs the link's own entry: {worst}"
    );
    // ... and the restriction matters: on every link, or on none, the arm moves
    // otherwise.
    let everywhere =
        Model::from_toml(&LINK3.replace("links = [\"link3\"]\n", ""), "all.toml", &ds).unwrap();
    for (what, other) in [("no effect", base.clone()), ("every link", everywhere)] {
        let d = worst_relative(&with, &sim(&ds, &other));
        assert!(d > 1e-4, "link 3 alone against {what}: {d}");
    }

    // The written scenario: link 3 taken out of "*" with the effect, simulating as the
    // model does.
    let copy = dir.path().join("written");
    am.write(&copy, "written").unwrap();
    let arm_file = copy.join(&am.scenario);
    let text =
        longreach_ident::arm_scenario::arm_scenario_text(&ds, &truth, &arm_file, "test").unwrap();
    assert!(text.contains("link = \"link3\""), "{text}");
    std::fs::write(&arm_file, &text).unwrap();
    let written = Dataset::load(&copy).unwrap();
    let worst = worst_relative(&with, &sim(&written, &base));
    assert!(worst <= 1e-9, "written scenario vs the model: {worst}");

    // Errors, located, each with its fix.
    let bad = |text: &str, ds: &Dataset, what: &str| {
        let e = Model::from_toml(text, "m.toml", ds)
            .unwrap_err()
            .to_string();
        assert!(e.contains(what) && e.contains("m.toml"), "{e}");
    };
    bad(
        &LINK3.replace("link3", "link9"),
        &ds,
        "link `link9` is not a flexible link",
    );
    bad(
        &LINK3.replace("links", "joints"),
        &ds,
        "acts on flexible links, not at joints",
    );
    bad(
        "[[effect]]\nname = \"joint_friction\"\nlinks = [\"link3\"]\n",
        &ds,
        "does not act on a link's bending",
    );
    bad(
        &format!(
            "{LINK3}{}",
            LINK3.replace("[\"link3\"]", "[\"link2\", \"link3\"]")
        ),
        &ds,
        "given twice on link3",
    );
    let rigid = Dataset::load(root().join("data/examples/example_arm_control")).unwrap();
    bad(LINK3, &rigid, "not a flexible link");
}

/// Two flexible links of one tube, made otherwise: hidden as `link_flexibility` per
/// link (link 2 at 0.5 of its scenario `E I`, link 4 at 0.2), one `ei_scale` for both
/// is a compromise above the margin at which `diagnose` refines a winner; the split per
/// link (`split_per_joint`, which `diagnose` then runs) is kept, ends at the floor and
/// recovers each link's scale within 5%.
#[test]
fn link_flexibility_is_split_per_link() {
    use longreach_drive::effects;
    use longreach_ident::analysis::{fit_model, prepared_at_step, split_per_joint};
    let dir = tempfile::tempdir().unwrap();
    let two = EVERY_LINK.replace("\"*\"", "\"link2\"") + &EVERY_LINK.replace("\"*\"", "\"link4\"");
    let scenario = flex_scenario(dir.path(), "two.toml", &two);
    let mut opt = ArmMovesOptions::new(scenario, 11);
    opt.duration_s = 1.5;
    opt.moves = vec![
        ArmMove {
            joint: "j2".into(),
            move_rad: 0.05,
            start_s: 0.2,
            payload_kg: None,
        },
        ArmMove {
            joint: "j4".into(),
            move_rad: 0.1,
            start_s: 0.2,
            payload_kg: None,
        },
    ];
    let plan = arm_plan(&opt).unwrap();
    let truth_text = "[[effect]]\nname = \"link_flexibility\"\nlinks = [\"link2\"]\n\
        [effect.params.ei_scale]\nvalue = 0.5\n\
        [[effect]]\nname = \"link_flexibility\"\nlinks = [\"link4\"]\n\
        [effect.params.ei_scale]\nvalue = 0.2\n";
    let truth = Model::from_toml(truth_text, "truth.toml", &plan).unwrap();
    let path = dir.path().join("data");
    arm_moves(&truth, &plan, &opt)
        .unwrap()
        .write(&path, "two tubes")
        .unwrap();
    let ds = Dataset::load(&path).unwrap();
    let base = Model::baseline(&ds).unwrap();
    let (prep, _) = prepared_at_step(&ds, &base).unwrap();
    let t = std::time::Instant::now();
    let shared = fit_model(
        &prep,
        &base.with_effect(effects::find("link_flexibility").unwrap()),
    )
    .unwrap();
    let (s, split) = split_per_joint(&prep, &shared, 0)
        .unwrap()
        .expect("a split");
    eprintln!(
        "{:.1} s: shared {:.4} {:?}, per link {:.4} (floor {:.4}) {:?}",
        t.elapsed().as_secs_f64(),
        s.nrmse_shared,
        s.shared,
        s.nrmse,
        shared.noise_floor,
        s.joints
    );
    assert_eq!(s.per, "link");
    assert!(s.kept, "score {}", s.score);
    assert!(
        s.nrmse_shared > longreach_ident::analysis::REFINE_MARGIN * shared.noise_floor,
        "shared {} vs floor {}",
        s.nrmse_shared,
        shared.noise_floor
    );
    assert!(
        split.nrmse < 1.5 * split.noise_floor,
        "per link {} vs floor {}",
        split.nrmse,
        split.noise_floor
    );
    for (link, want) in [("link2", 0.5), ("link4", 0.2)] {
        let j = s.joints.iter().find(|j| j.joint == link).unwrap();
        let got = j.values[0].1;
        assert!(
            (got / want - 1.0).abs() < 0.05,
            "{link}: ei_scale {got} vs {want}"
        );
    }
}
