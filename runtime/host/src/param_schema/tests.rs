use super::*;

/// The shapes `schemars` writes for serde types: a required choice by
/// `$ref`, a nullable fixed array, an optional `$ref` table, an untagged
/// number-or-three, an array of tables, a tagged enum (`oneOf` objects).
const SCHEMA: &str = r##"{
  "type": "object",
  "properties": {
    "field": {"description": "The field.\n\nMore.", "$ref": "#/$defs/Kind"},
    "centre": {"description": "Fixed point, mm.", "type": ["array", "null"], "default": null,
               "items": {"type": "number"}, "minItems": 3, "maxItems": 3, "unit": "mm"},
    "ramp_frames": {"type": "integer", "default": 1, "minimum": 1, "unit": "frames"},
    "constraint": {"anyOf": [{"type": "number"}, {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}]},
    "materials": {"type": "array", "items": {"$ref": "#/$defs/Material"}},
    "proxy": {"anyOf": [{"$ref": "#/$defs/Proxy"}, {"type": "null"}]}
  },
  "additionalProperties": false,
  "required": ["field", "materials"],
  "$defs": {
    "Kind": {"oneOf": [{"type": "string", "const": "affine"}, {"type": "string", "const": "twist"}]},
    "Material": {"type": "object", "required": ["youngs_modulus"], "properties": {
        "youngs_modulus": {"type": "number", "minimum": 0, "unit": "Pa", "description": "Young's modulus, Pa."},
        "name": {"type": ["string", "null"]}}},
    "Proxy": {"oneOf": [
        {"type": "object", "properties": {"kind": {"type": "string", "const": "uniform"}, "step": {"type": "integer", "minimum": 1}}, "required": ["kind", "step"]},
        {"type": "object", "properties": {"kind": {"type": "string", "const": "file"}, "path": {"type": "string"}}, "required": ["kind", "path"]}]}
  }
}"##;

fn schema() -> ParamSchema {
    ParamSchema::from_json(SCHEMA).unwrap()
}

fn check(toml_text: &str) -> Vec<String> {
    schema().check(&toml_text.parse().unwrap())
}

#[test]
fn keys_types_units_ranges_and_defaults_are_read() {
    let s = schema();
    let names: Vec<&str> = s.params.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "field",
            "materials",
            "centre",
            "constraint",
            "proxy",
            "ramp_frames"
        ]
    );
    let field = s.get("field").unwrap();
    assert_eq!(
        field.kind,
        ParamKind::Choice(vec!["affine".into(), "twist".into()])
    );
    assert!(field.required);
    assert_eq!(field.doc, "The field.");
    let centre = s.get("centre").unwrap();
    assert!(!centre.required && centre.default.is_none());
    assert_eq!(centre.kind.to_string(), "[number; 3]");
    assert_eq!(centre.unit.as_deref(), Some("mm"));
    let ramp = s.get("ramp_frames").unwrap();
    assert_eq!(
        (ramp.minimum, ramp.default.as_deref()),
        (Some(1.0), Some("1"))
    );
    assert_eq!(
        s.get("constraint").unwrap().kind.to_string(),
        "number | [number; 3]"
    );
    assert_eq!(s.get("materials").unwrap().kind.to_string(), "[table]");
    assert!(!s.get("proxy").unwrap().required);
}

#[test]
fn a_conforming_table_has_no_problems() {
    let ok = "field = \"twist\"\nmaterials = [{ youngs_modulus = 3000 }, { youngs_modulus = 2.5e4, name = \"bone\" }]\n\
              centre = [0, 1.5, 2]\nconstraint = [0.1, 0.1, 0.2]\nproxy = { kind = \"uniform\", step = 4 }";
    assert_eq!(check(ok), Vec::<String>::new());
    assert_eq!(
        check("field = \"affine\"\nmaterials = []\nconstraint = 0.5"),
        Vec::<String>::new()
    );
}

#[test]
fn every_problem_is_reported_with_its_path() {
    let issues = check(
        "fild = \"twist\"\nmaterials = [{ youngs_modulus = -1 }, { name = \"x\" }]\n\
         centre = [0, 1]\nramp_frames = 0\nproxy = { kind = \"uniform\", step = 0 }\nwhatever = 1",
    );
    let all = issues.join("\n");
    for needle in [
        "unknown key `fild`: did you mean `field`?",
        "`materials[0].youngs_modulus` = -1 Pa is below its minimum 0 Pa",
        "`materials[1].youngs_modulus` is missing",
        "`centre` has 2 items, expected 3",
        "`ramp_frames` = 0 frames is below its minimum 1 frames",
        "`proxy.step` = 0 is below its minimum 1",
        "unknown key `whatever` (known: field, materials, centre",
        "`field` is missing",
    ] {
        assert!(all.contains(needle), "missing {needle:?} in:\n{all}");
    }
    assert_eq!(issues.len(), 8, "{all}");
}

#[test]
fn wrong_types_and_choices_are_named() {
    let all = check("field = \"bend\"\nmaterials = 3\nconstraint = \"x\"\ncentre = [0, nan, 1]")
        .join("\n");
    assert!(
        all.contains("`field` = \"bend\" is not one of \"affine\" | \"twist\""),
        "{all}"
    );
    assert!(
        all.contains("`materials` is an integer, expected [table]"),
        "{all}"
    );
    assert!(
        all.contains("`constraint` is a string, expected number"),
        "{all}"
    );
    assert!(
        all.contains("`centre[1]` = NaN is not a finite number"),
        "{all}"
    );
}

#[test]
fn the_text_table_lists_nested_keys() {
    let t = schema().to_text();
    assert!(t.starts_with("key"), "{t}");
    assert!(t.contains("  youngs_modulus"), "{t}");
    assert!(
        t.lines()
            .any(|l| l.starts_with("ramp_frames") && l.contains(">= 1") && l.contains("frames")),
        "{t}"
    );
    assert!(
        t.lines()
            .any(|l| l.starts_with("field") && l.contains("required")),
        "{t}"
    );
}

#[test]
fn schemas_outside_the_subset_are_refused() {
    assert!(ParamSchema::from_json("not json").is_err());
    let e =
        ParamSchema::from_json(r##"{"type":"object","properties":{"a":{"$ref":"#/$defs/Nope"}}}"##)
            .unwrap_err();
    assert!(e.to_string().contains("names no definition"), "{e}");
    let cycle = r##"{"type":"object","properties":{"a":{"$ref":"#/$defs/A"}},"$defs":{"A":{"type":"object","properties":{"a":{"$ref":"#/$defs/A"}}}}}"##;
    let e = ParamSchema::from_json(cycle).unwrap_err();
    assert!(e.to_string().contains("too deep"), "{e}");
}
