//! docs/scene.md against the parser. Every table of the scene schema is probed with a key
//! it does not have (`__probe__`): the parser refuses it (`deny_unknown_fields`) and its
//! error lists every key the table accepts. The reference section of that table in
//! docs/scene.md must list exactly those keys; every named choice (`integrator`, `kind`,
//! `shape`, ...) probed the same way must have each of its values in its row; and every
//! default the page gives as a single value must be what the parser fills in. The page's
//! TOML examples parse.
//!
//! The page's reference sections are headings whose backtick spans name the table
//! (``### `[render]` ``, ``#### `medium.field` with `kind = "expr"` ``), each followed by a
//! table of rows ``| `key` | type | default | unit | allowed values | meaning |``.
//!
//! A new table in the schema needs a [`Site`] here (a new key of an existing table fails
//! this test until the page lists it).
//!
//! Over 600 lines: one concept, docs/scene.md held against the parser, table by table.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use grin_scene::{SceneError, parse_scene};

/// The key no table has.
const PROBE: &str = "__probe__";

/// A camera, for the sites that probe something else.
const CAM: &str = "camera = { position = [0.0, 0.0, -4.0], look_at = [0.0, 0.0, 0.0] }\n";

/// One row of a reference table: its cells (the key's cell first).
type Row = Vec<String>;

/// The page's reference sections: id -> key -> row.
fn doc_sections(text: &str) -> BTreeMap<String, BTreeMap<String, Row>> {
    let mut out: BTreeMap<String, BTreeMap<String, Row>> = BTreeMap::new();
    let mut current: Option<String> = None;
    let mut fenced = false;
    for line in text.lines() {
        if line.starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        if line.starts_with('#') {
            let spans: Vec<String> = backticked(line)
                .into_iter()
                .map(|s| s.trim_matches(|c| c == '[' || c == ']').to_owned())
                .collect();
            current = (!spans.is_empty()).then(|| spans.join(" "));
            continue;
        }
        let Some(id) = &current else { continue };
        if !line.starts_with("| `") {
            continue;
        }
        let cells: Vec<String> = line
            .trim()
            .trim_matches('|')
            .split('|')
            .map(|c| c.trim().to_owned())
            .collect();
        let key = backticked(&cells[0])
            .into_iter()
            .next()
            .expect("a row's first cell names its key");
        let previous = out
            .entry(id.clone())
            .or_default()
            .insert(key.clone(), cells);
        assert!(
            previous.is_none(),
            "docs/scene.md, `{id}`: `{key}` is listed twice"
        );
    }
    out
}

/// The `...` spans of a line, in order.
fn backticked(line: &str) -> Vec<String> {
    line.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_owned)
        .collect()
}

fn doc() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/scene.md");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

/// The parse error's message for `text`; panics when it parses.
fn parse_error(text: &str) -> String {
    match parse_scene(text, Path::new("probe.toml")) {
        Ok(_) => panic!("test bug: the probe parsed:\n{text}"),
        Err(SceneError::Parse { message, .. }) => message,
        Err(e) => panic!("test bug: not a parse error: {e}\n{text}"),
    }
}

/// The names a refusal lists after "expected" (the keys or the values accepted).
fn expected_names(message: &str) -> BTreeSet<String> {
    let (_, list) = message
        .split_once("expected")
        .unwrap_or_else(|| panic!("no list of what is expected in `{message}`"));
    backticked(list).into_iter().collect()
}

/// A table of the schema: its id on the page, a scene in which `@` marks the start of
/// the table's inline body (`{ @key = ... }`, or `{ @ }` for a table that is all
/// defaults), and where the table is in the serialized scene.
struct Site {
    id: &'static str,
    text: String,
    at: Vec<Seg>,
}

#[derive(Debug)]
enum Seg {
    Key(&'static str),
    Index(usize),
}

impl Site {
    fn new(id: &'static str, text: impl Into<String>, at: &[&'static str]) -> Self {
        let at = at
            .iter()
            .map(|k| match k.parse() {
                Ok(i) => Seg::Index(i),
                Err(_) => Seg::Key(k),
            })
            .collect();
        Site {
            id,
            text: text.into(),
            at,
        }
    }

    /// The scene as it is (`probe` false) or with the unknown key in the table.
    fn scene(&self, probe: bool) -> String {
        assert!(self.text.contains('@'), "test bug: no @ in {}", self.id);
        let key = format!("{PROBE} = 0");
        if self.text.contains("{ @ }") {
            let with = if probe {
                format!("{{ {key} }}")
            } else {
                "{}".into()
            };
            self.text.replace("{ @ }", &with)
        } else {
            let with = if probe {
                format!("{key}, ")
            } else {
                String::new()
            };
            self.text.replace('@', &with)
        }
    }
}

fn medium(field: &str) -> String {
    format!(
        "{CAM}medium = {{ bounds = {{ sphere = {{ center = [0.0, 0.0, 0.0], radius = 1.0 }} }}, field = {field} }}\n"
    )
}

fn on_plane(material: &str) -> String {
    format!("{CAM}object = [{{ shape = {{ plane = {{}} }}, material = {material} }}]\n")
}

/// Every table of the schema that has keys of its own.
fn sites() -> Vec<Site> {
    const SPHERE: &str = "sphere = { center = [0.0, 0.0, 0.0], radius = 1.0 }";
    let field = |id, body: &str| Site::new(id, medium(body), &["medium", "field"]);
    let material = |id, name: &'static str, body: &str| {
        Site::new(
            id,
            on_plane(&format!("{{ {name} = {body} }}")),
            &["object", "0", "material", name],
        )
    };
    let vdb = |map: &str| {
        medium(&format!(
            "{{ kind = \"vdb\", path = \"g.vdb\", grid = \"g\", map = {map} }}"
        ))
    };
    let optics = |body: &str| {
        format!(
            "{}optics = {body}\n",
            medium("{ kind = \"uniform\", n = 1.1 }")
        )
    };
    vec![
        Site::new(
            "camera",
            "camera = { @position = [0.0, 0.0, -4.0], look_at = [0.0, 0.0, 0.0] }\n",
            &["camera"],
        ),
        Site::new(
            "object",
            format!("{CAM}object = [{{ @shape = {{ {SPHERE} }} }}]\n"),
            &["object", "0"],
        ),
        Site::new(
            "object.shape.sphere",
            format!(
                "{CAM}object = [{{ shape = {{ sphere = {{ @center = [0.0, 0.0, 0.0], radius = 1.0 }} }} }}]\n"
            ),
            &["object", "0", "shape", "sphere"],
        ),
        Site::new(
            "object.shape.plane",
            format!("{CAM}object = [{{ shape = {{ plane = {{ @ }} }} }}]\n"),
            &["object", "0", "shape", "plane"],
        ),
        Site::new(
            "object.shape.box",
            format!(
                "{CAM}object = [{{ shape = {{ box = {{ @min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }} }} }}]\n"
            ),
            &["object", "0", "shape", "box"],
        ),
        material("object.material.diffuse", "diffuse", "{ @ }"),
        material("object.material.checker", "checker", "{ @ }"),
        material("object.material.mirror", "mirror", "{ @ }"),
        material("object.material.metal", "metal", "{ @ }"),
        material("object.material.glass", "glass", "{ @ }"),
        material(
            "object.material.texture",
            "texture",
            "{ @path = \"t.png\", size = [1.0, 1.0] }",
        ),
        material("object.material.dots", "dots", "{ @ }"),
        Site::new(
            "medium",
            format!(
                "{CAM}medium = {{ @bounds = {{ {SPHERE} }}, field = {{ kind = \"uniform\", n = 1.1 }} }}\n"
            ),
            &["medium"],
        ),
        Site::new(
            "medium.bounds.sphere",
            format!(
                "{CAM}medium = {{ bounds = {{ sphere = {{ @center = [0.0, 0.0, 0.0], radius = 1.0 }} }}, field = {{ kind = \"uniform\", n = 1.1 }} }}\n"
            ),
            &["medium", "bounds", "sphere"],
        ),
        Site::new(
            "medium.bounds.box",
            format!(
                "{CAM}medium = {{ bounds = {{ box = {{ @min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }} }}, field = {{ kind = \"uniform\", n = 1.1 }} }}\n"
            ),
            &["medium", "bounds", "box"],
        ),
        field(
            "medium.field kind = \"uniform\"",
            "{ @kind = \"uniform\", n = 1.1 }",
        ),
        field(
            "medium.field kind = \"linear-n2\"",
            "{ @kind = \"linear-n2\", n0 = 1.2, k = 0.1 }",
        ),
        field(
            "medium.field kind = \"grin-rod\"",
            "{ @kind = \"grin-rod\", n0 = 1.5, a = 0.5 }",
        ),
        field(
            "medium.field kind = \"luneburg\"",
            "{ @kind = \"luneburg\" }",
        ),
        field(
            "medium.field kind = \"maxwell-fish-eye\"",
            "{ @kind = \"maxwell-fish-eye\", n0 = 2.0, a = 1.0 }",
        ),
        field("medium.field kind = \"eaton\"", "{ @kind = \"eaton\" }"),
        field(
            "medium.field kind = \"exponential-atmosphere\"",
            "{ @kind = \"exponential-atmosphere\", e = 1e-4, scale_height = 0.5 }",
        ),
        field(
            "medium.field kind = \"plume\"",
            "{ @kind = \"plume\", plumes = [{ a = 1e-4, center = [0.0, 0.0, 0.0], s = 0.3 }] }",
        ),
        Site::new(
            "medium.field.plumes",
            medium(
                "{ kind = \"plume\", plumes = [{ @a = 1e-4, center = [0.0, 0.0, 0.0], s = 0.3 }] }",
            ),
            &["medium", "field", "plumes", "0"],
        ),
        field(
            "medium.field kind = \"expr\"",
            "{ @kind = \"expr\", n = \"1.1\" }",
        ),
        field(
            "medium.field kind = \"noise\"",
            "{ @kind = \"noise\", amplitude = 0.01 }",
        ),
        field(
            "medium.field kind = \"vdb\"",
            "{ @kind = \"vdb\", path = \"g.vdb\", grid = \"g\", map = { index = {} } }",
        ),
        Site::new(
            "medium.field.map.index",
            vdb("{ index = { @ } }"),
            &["medium", "field", "map", "index"],
        ),
        Site::new(
            "medium.field.map.linear",
            vdb("{ linear = { @k = 1e-4 } }"),
            &["medium", "field", "map", "linear"],
        ),
        Site::new(
            "medium.field.map.gladstone-dale",
            vdb("{ gladstone-dale = { @ } }"),
            &["medium", "field", "map", "gladstone-dale"],
        ),
        field(
            "medium.field kind = \"baked\"",
            "{ @kind = \"baked\", path = \"f.grinf\" }",
        ),
        Site::new(
            "light.point",
            format!(
                "{CAM}light = [{{ point = {{ @position = [0.0, 1.0, 0.0], intensity = [1.0, 1.0, 1.0] }} }}]\n"
            ),
            &["light", "0", "point"],
        ),
        Site::new(
            "light.directional",
            format!(
                "{CAM}light = [{{ directional = {{ @direction = [0.0, -1.0, 0.0], intensity = [1.0, 1.0, 1.0] }} }}]\n"
            ),
            &["light", "0", "directional"],
        ),
        Site::new(
            "sky.gradient",
            format!(
                "{CAM}sky = {{ gradient = {{ @horizon = [1.0, 1.0, 1.0], zenith = [0.0, 0.0, 1.0], ground = [0.1, 0.1, 0.1] }} }}\n"
            ),
            &["sky", "gradient"],
        ),
        Site::new(
            "sky.map",
            format!("{CAM}sky = {{ map = {{ @path = \"sky.exr\" }} }}\n"),
            &["sky", "map"],
        ),
        Site::new(
            "sky.plate",
            format!("{CAM}sky = {{ plate = {{ @path = \"plate.png\" }} }}\n"),
            &["sky", "plate"],
        ),
        Site::new("render", format!("{CAM}render = {{ @ }}\n"), &["render"]),
        Site::new(
            "render.step.heuristic",
            format!("{CAM}render = {{ step = {{ heuristic = {{ @min = 0.01, max = 0.1 }} }} }}\n"),
            &["render", "step", "heuristic"],
        ),
        Site::new(
            "render.step.adaptive",
            format!("{CAM}render = {{ step = {{ adaptive = {{ @tolerance = 1e-5 }} }} }}\n"),
            &["render", "step", "adaptive"],
        ),
        Site::new(
            "animation",
            format!("{CAM}animation = {{ @frames = [1, 2] }}\n"),
            &["animation"],
        ),
        Site::new(
            "optics",
            optics("{ @mode = \"displacement\" }"),
            &["optics"],
        ),
        Site::new(
            "optics.plane",
            optics(
                "{ mode = \"bos\", plane = { @point = [0.0, 0.0, 4.0], normal = [0.0, 0.0, -1.0] } }",
            ),
            &["optics", "plane"],
        ),
        Site::new(
            "optics.knife",
            optics("{ mode = \"schlieren\", knife = { @ } }"),
            &["optics", "knife"],
        ),
        Site::new(
            "optics.fringes",
            optics("{ mode = \"interferogram\", fringes = { @ } }"),
            &["optics", "fringes"],
        ),
        Site::new(
            "optics.dots",
            optics("{ mode = \"displacement\", dots = { @ } }"),
            &["optics", "dots"],
        ),
        Site::new(
            "optics.screen",
            optics("{ mode = \"shadowgraph\", screen = { @ } }"),
            &["optics", "screen"],
        ),
        Site::new("sensor", format!("{CAM}sensor = {{ @ }}\n"), &["sensor"]),
    ]
}

/// A named choice: the section and row on the page, and a scene that names a value no
/// choice has.
fn choices() -> Vec<(&'static str, &'static str, String)> {
    let field = |body: &str| medium(body);
    let vdb = |extra: &str| {
        medium(&format!(
            "{{ kind = \"vdb\", path = \"g.vdb\", grid = \"g\", map = {{ index = {{}} }}{extra} }}"
        ))
    };
    vec![
        (
            "object",
            "shape",
            format!("{CAM}object = [{{ shape = {{ {PROBE} = {{}} }} }}]\n"),
        ),
        (
            "object",
            "material",
            on_plane(&format!("{{ {PROBE} = {{}} }}")),
        ),
        (
            "medium",
            "bounds",
            format!(
                "{CAM}medium = {{ bounds = {{ {PROBE} = {{}} }}, field = {{ kind = \"uniform\", n = 1.1 }} }}\n"
            ),
        ),
        (
            "medium",
            "field",
            field(&format!("{{ kind = \"{PROBE}\" }}")),
        ),
        (
            "medium.field kind = \"linear-n2\"",
            "axis",
            field(&format!(
                "{{ kind = \"linear-n2\", n0 = 1.2, k = 0.1, axis = \"{PROBE}\" }}"
            )),
        ),
        (
            "medium.field kind = \"grin-rod\"",
            "axis",
            field(&format!(
                "{{ kind = \"grin-rod\", n0 = 1.5, a = 0.5, axis = \"{PROBE}\" }}"
            )),
        ),
        (
            "medium.field kind = \"exponential-atmosphere\"",
            "axis",
            field(&format!(
                "{{ kind = \"exponential-atmosphere\", e = 1e-4, scale_height = 0.5, axis = \"{PROBE}\" }}"
            )),
        ),
        (
            "medium.field kind = \"noise\"",
            "noise",
            field(&format!(
                "{{ kind = \"noise\", amplitude = 0.01, noise = \"{PROBE}\" }}"
            )),
        ),
        (
            "medium.field kind = \"vdb\"",
            "map",
            medium(&format!(
                "{{ kind = \"vdb\", path = \"g.vdb\", grid = \"g\", map = {{ {PROBE} = {{}} }} }}"
            )),
        ),
        (
            "medium.field kind = \"vdb\"",
            "up",
            vdb(&format!(", up = \"{PROBE}\"")),
        ),
        (
            "medium.field kind = \"vdb\"",
            "non_finite",
            vdb(&format!(", non_finite = \"{PROBE}\"")),
        ),
        (
            "medium.field kind = \"baked\"",
            "interpolation",
            field(&format!(
                "{{ kind = \"baked\", path = \"f.grinf\", interpolation = \"{PROBE}\" }}"
            )),
        ),
        (
            "render",
            "integrator",
            format!("{CAM}render = {{ integrator = \"{PROBE}\" }}\n"),
        ),
        (
            "render",
            "step",
            format!("{CAM}render = {{ step = {{ {PROBE} = 1.0 }} }}\n"),
        ),
        (
            "render",
            "exit",
            format!("{CAM}render = {{ exit = \"{PROBE}\" }}\n"),
        ),
        (
            "optics",
            "mode",
            format!("{CAM}optics = {{ mode = \"{PROBE}\" }}\n"),
        ),
    ]
}

/// Tables whose keys are themselves the choice (`[[light]] point = {..}`, `[sky]
/// gradient = {..}`): the section lists exactly the values.
fn keyed_choices() -> Vec<(&'static str, String)> {
    vec![
        ("light", format!("{CAM}light = [{{ {PROBE} = {{}} }}]\n")),
        ("sky", format!("{CAM}sky = {{ {PROBE} = {{}} }}\n")),
    ]
}

#[test]
fn every_table_lists_exactly_the_keys_the_parser_accepts() {
    let sections = doc_sections(&doc());
    let mut problems = Vec::new();
    let mut compare = |id: &str, accepted: BTreeSet<String>| {
        let Some(rows) = sections.get(id) else {
            problems.push(format!("no reference table for `{id}`"));
            return;
        };
        let listed: BTreeSet<String> = rows.keys().cloned().collect();
        for key in accepted.difference(&listed) {
            problems.push(format!(
                "`{id}`: the parser accepts `{key}`, which the table does not list"
            ));
        }
        for key in listed.difference(&accepted) {
            problems.push(format!(
                "`{id}`: the table lists `{key}`, which the parser refuses"
            ));
        }
    };
    for site in sites() {
        let message = parse_error(&site.scene(true));
        assert!(
            message.contains(&format!("unknown field `{PROBE}`")),
            "{}: {message}",
            site.id
        );
        compare(site.id, expected_names(&message));
    }
    for (id, text) in keyed_choices() {
        let message = parse_error(&text);
        assert!(message.contains("unknown variant"), "{id}: {message}");
        compare(id, expected_names(&message));
    }
    // The top level: a section for every table.
    let message = parse_error(&format!("{CAM}{PROBE} = 0\n"));
    for table in expected_names(&message) {
        if !sections.contains_key(&table) {
            problems.push(format!("no reference section for the table `{table}`"));
        }
    }
    // Every section with rows is one the test probes.
    let probed: BTreeSet<String> = sites()
        .iter()
        .map(|s| s.id.to_owned())
        .chain(keyed_choices().into_iter().map(|(id, _)| id.to_owned()))
        .collect();
    for id in sections.keys() {
        if !probed.contains(id) {
            problems.push(format!(
                "`{id}` has a key table that tests/scene_doc.rs does not probe (add a Site)"
            ));
        }
    }
    assert!(
        problems.is_empty(),
        "docs/scene.md is out of step with the scene parser:\n  {}",
        problems.join("\n  ")
    );
}

#[test]
fn every_choice_lists_every_value_the_parser_accepts() {
    let sections = doc_sections(&doc());
    let mut problems = Vec::new();
    for (id, key, text) in choices() {
        let message = parse_error(&text);
        assert!(
            message.contains(&format!("unknown variant `{PROBE}`")),
            "{id}.{key}: {message}"
        );
        let Some(row) = sections.get(id).and_then(|rows| rows.get(key)) else {
            problems.push(format!("`{id}`: no row for `{key}`"));
            continue;
        };
        let mentioned: BTreeSet<String> = row
            .iter()
            .flat_map(|cell| backticked(cell))
            .map(|s| s.trim_matches('"').to_owned())
            .collect();
        for value in expected_names(&message) {
            if !mentioned.contains(&value) {
                problems.push(format!(
                    "`{id}`, row `{key}`: the parser accepts `{value}`, which the row does not name"
                ));
            }
        }
    }
    assert!(
        problems.is_empty(),
        "docs/scene.md is out of step with the scene parser:\n  {}",
        problems.join("\n  ")
    );
}

#[test]
fn every_default_given_as_a_value_is_the_parser_s() {
    let sections = doc_sections(&doc());
    let mut problems = Vec::new();
    let mut checked = 0;
    for site in sites() {
        let text = site.scene(false);
        let scene = parse_scene(&text, Path::new("site.toml"))
            .unwrap_or_else(|e| panic!("test bug: {}: {e}\n{text}", site.id));
        let mut value = toml::Value::try_from(&scene).expect("a scene serializes");
        for seg in &site.at {
            value = match seg {
                Seg::Key(k) => value.get(*k).cloned(),
                Seg::Index(i) => value.get(*i).cloned(),
            }
            .unwrap_or_else(|| panic!("test bug: {}: no {seg:?} in {text}", site.id));
        }
        let Some(rows) = sections.get(site.id) else {
            continue; // reported by the key test
        };
        for (key, row) in rows {
            let Some(default) = literal(&row[2]) else {
                continue;
            };
            checked += 1;
            match value.get(key.as_str()) {
                None => problems.push(format!(
                    "`{}.{key}`: the page's default is {default}, the parser leaves it unset",
                    site.id
                )),
                Some(actual) if !same(actual, &default) => problems.push(format!(
                    "`{}.{key}`: the page's default is {default}, the parser's is {actual}",
                    site.id
                )),
                Some(_) => {}
            }
        }
    }
    assert!(
        problems.is_empty(),
        "docs/scene.md gives defaults the parser does not:\n  {}",
        problems.join("\n  ")
    );
    // The page gives most defaults as values: a change of format must not skip them all.
    assert!(checked >= 60, "only {checked} defaults were compared");
}

#[test]
fn the_page_s_examples_parse() {
    let mut examples = Vec::new();
    let mut block: Option<String> = None;
    for line in doc().lines() {
        match (&mut block, line) {
            (None, "```toml") => block = Some(String::new()),
            (Some(text), "```") => {
                examples.push(std::mem::take(text));
                block = None;
            }
            (Some(text), line) => {
                text.push_str(line);
                text.push('\n');
            }
            (None, _) => {}
        }
    }
    assert!(examples.len() >= 3, "found {} examples", examples.len());
    for example in examples {
        // A list of fields, one a line, goes into a medium each; a fragment gets a camera.
        let scenes: Vec<String> = if example.starts_with("field = ") {
            example
                .lines()
                .map(|line| {
                    format!("{CAM}[medium]\nbounds = {{ sphere = {{ center = [0.0, 0.0, 0.0], radius = 1.0 }} }}\n{line}\n")
                })
                .collect()
        } else if example.contains("[camera]") {
            vec![example]
        } else {
            vec![format!("{CAM}{example}")]
        };
        for text in scenes {
            if let Err(e) = parse_scene(&text, Path::new("docs/scene.md")) {
                panic!("an example of docs/scene.md does not parse: {e}\n{text}");
            }
        }
    }
}

/// A default cell that is one TOML value in backticks (`640`, `"hermite"`,
/// `{ auto = 1e-4 }`), parsed; `None` for prose, "required" and "none".
fn literal(cell: &str) -> Option<toml::Value> {
    let inner = cell.strip_prefix('`')?.strip_suffix('`')?;
    if inner.contains('`') {
        return None;
    }
    let table: toml::Table = format!("v = {inner}").parse().ok()?;
    table.get("v").cloned()
}

/// Equal as values: numbers within rounding, integers and floats alike.
fn same(a: &toml::Value, b: &toml::Value) -> bool {
    use toml::Value;
    let number = |v: &Value| match v {
        Value::Integer(i) => Some(*i as f64),
        Value::Float(x) => Some(*x),
        _ => None,
    };
    match (a, b) {
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| same(p, q))
        }
        (Value::Table(x), Value::Table(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| same(v, w)))
        }
        _ => match (number(a), number(b)) {
            (Some(x), Some(y)) => (x - y).abs() <= 1e-12 * x.abs().max(y.abs()),
            _ => a == b,
        },
    }
}
