//! The form's TOML against the real plugins' schemas (from
//! `target/<profile>/`, where `cargo build` puts them).

use super::*;
use std::path::PathBuf;
use voxflex_runtime::plugin_loader::list;

/// `target/<profile>`, the built plugins checked there.
fn plugin_dir() -> PathBuf {
    voxflex_integration_tests::plugin_dir(&["chainmail"])
}

fn schema(name: &str) -> ParamSchema {
    list(&[plugin_dir()])
        .plugins
        .into_iter()
        .find(|p| p.plugin.name == name)
        .unwrap_or_else(|| panic!("plugin {name} on the search path"))
        .plugin
        .params
}

#[test]
fn every_plugins_defaults_make_a_table_its_schema_accepts() {
    let listing = list(&[plugin_dir()]);
    let shipped = [
        "affine",
        "chainmail",
        "mass-spring",
        "corotational-fem",
        "raycast",
    ];
    for name in shipped {
        assert!(
            listing.plugins.iter().any(|p| p.plugin.name == name),
            "{name} is not built"
        );
    }
    for p in listing.plugins.iter().filter(|p| p.loads) {
        let mut form = ParamForm::new(&p.plugin.name, &p.plugin.params, &toml::Table::new());
        let text = form.toml_text().expect("defaults are TOML");
        let back: toml::Table = text.parse().expect("the text parses back");
        assert_eq!(back, form.table().expect("table"), "{}", p.plugin.name);
        let issues = p.plugin.params.check(&back);
        assert!(issues.is_empty(), "{}: {text}\n{issues:?}", p.plugin.name);
        assert!(form.check(), "{}: {:?}", p.plugin.name, form.fields);
    }
}

#[test]
fn a_scene_table_round_trips_through_the_widgets() {
    let given: toml::Table = r#"
        downsample = 2
        rest_tolerance = 0.001
        algorithm = "sequential"
        block = [4, 4, 2]
        materials = [{ range = [0.1, 2.0], constraint = 0.5 }]
    "#
    .parse()
    .expect("TOML");
    let form = ParamForm::new("chainmail", &schema("chainmail"), &given);
    let field = |k: &str| {
        &form
            .fields
            .iter()
            .find(|f| f.spec.name == k)
            .expect(k)
            .value
    };
    assert_eq!(field("downsample"), &FieldValue::Integer(2));
    assert_eq!(field("algorithm"), &FieldValue::Choice("sequential".into()));
    assert_eq!(
        field("block"),
        &FieldValue::Numbers {
            values: vec![4.0, 4.0, 2.0],
            integer: true
        }
    );
    assert!(matches!(field("materials"), FieldValue::Toml(_)));
    let back: toml::Table = form.toml_text().expect("TOML").parse().expect("parses");
    for (k, v) in &given {
        assert_eq!(back.get(k), Some(v), "key {k}");
    }
    // Defaults fill the rest (`crop` has none and stays out).
    assert_eq!(
        back.get("relaxation_iterations"),
        Some(&toml::Value::Integer(10))
    );
    assert!(!back.contains_key("crop"));
}

#[test]
fn problems_are_filed_under_the_key_they_name() {
    let mut form = ParamForm::new("chainmail", &schema("chainmail"), &toml::Table::new());
    let at =
        |form: &ParamForm, k: &str| form.fields.iter().position(|f| f.spec.name == k).expect(k);
    let d = at(&form, "downsample");
    form.fields[d].value = FieldValue::Integer(0);
    assert!(!form.check());
    assert!(!form.fields[d].issues.is_empty(), "{:?}", form.general);
    let m = at(&form, "materials");
    form.fields[d].value = FieldValue::Integer(1);
    form.fields[m].value = FieldValue::Toml("[{ range = [0.1,".into());
    assert!(!form.check());
    assert!(form.fields[d].issues.is_empty());
    assert!(!form.fields[m].issues.is_empty());
    // A session error naming a key lands there too.
    form.file_issues(&["model: `materials[0].constraint` = 9 is over 8".into()]);
    assert_eq!(form.fields[m].issues.len(), 1);
    form.file_issues(&["the plugin refused the table".into()]);
    assert_eq!(form.general.len(), 1);
}
