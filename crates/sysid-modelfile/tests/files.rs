//! Model files: the built-ins parse and write back unchanged; malformed files get one
//! line with the line and column of the fault.

use sysid_modelfile::{ModelFile, builtin};

#[test]
fn every_builtin_parses_and_reads_back_bit_identically_after_writing() {
    for name in builtin::names() {
        let model = builtin::model(name)
            .expect("known")
            .unwrap_or_else(|e| panic!("{e}"));
        let text = model.to_toml(&[("fitted_by".into(), "\"test\"".into())]);
        let again = ModelFile::parse(&text, "written").unwrap_or_else(|e| panic!("{e}\n{text}"));
        // the same text again (the syntax trees differ only in their spans)
        assert_eq!(again.to_toml(&[]), model.to_toml(&[]), "{name}:\n{text}");
        assert_eq!(again.spec().parameters, model.spec().parameters, "{name}");
        // with other values, still bit-identical
        let theta: Vec<f64> = model
            .free_values()
            .iter()
            .map(|v| v * (1.0 + 1e-13) + 1e-300)
            .collect();
        let moved = model.with_values(&theta);
        let back = ModelFile::parse(&moved.to_toml(&[]), "moved").unwrap();
        let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(back.free_values()), bits(theta.clone()), "{name}");
    }
}

const GOOD: &str = r#"format = 1
states = ["x", "v"]
inputs = ["u"]
outputs = ["y"]

[parameters]
a = { value = 0.5 }
k = { value = 2.0, min = 0 }
q = { value = 0.1, min = 0 }
dt = 0.1

[transition]
x = "x + dt*v"
v = "v - dt*(a*sin(x) + v/k) + u"

[observation]
y = "x"

[noise]
x = "q"
v = "q"
y = 0.5

[initial]
x = { mean = 0, variance = 1 }
v = { mean = 0, variance = 1 }
"#;

/// Replaces the first `from` of the good file with `to`.
fn edit(from: &str, to: &str) -> String {
    assert!(GOOD.contains(from), "{from}");
    GOOD.replacen(from, to, 1)
}

#[test]
fn the_good_file_parses() {
    let m = ModelFile::parse(GOOD, "m.toml").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(m.free_names(), ["a", "k", "q"]);
    // a enters linearly, but q is the variance of two states and k is under a division
    assert!(m.affine().is_none());
}

#[test]
fn every_malformed_file_gets_one_line_with_its_line_and_column() {
    // (edit, expected line:column, words of the message)
    let cases: Vec<(String, (usize, usize), &str)> = vec![
        // TOML syntax
        (edit("format = 1", "format = = 1"), (1, 10), "extra `=`"),
        (
            edit("format = 1", "format = 2"),
            (1, 10),
            "format 2 is not known",
        ),
        (
            edit("[initial]", "[initial]\nz = { mean = 0, variance = 1 }"),
            (25, 5),
            "not a state",
        ),
        (
            edit("format = 1", "format = 1\ncolour = 3"),
            (2, 1),
            "unknown field `colour`",
        ),
        // expressions
        (
            edit("\"x + dt*v\"", "\"x + dt*w\""),
            (13, 13),
            "unknown name \"w\"",
        ),
        (
            edit("\"x + dt*v\"", "\"x + dt*(v\""),
            (13, 13),
            "expected ')'",
        ),
        (
            edit("\"x + dt*v\"", "\"x + * v\""),
            (13, 10),
            "expected a number",
        ),
        (
            edit("a*sin(x)", "a*sin(x, v)"),
            (14, 16),
            "sin takes 1 argument",
        ),
        (edit("a*sin(x)", "a*sinh(x)"), (14, 16), "unknown function"),
        (edit("y = \"x\"", "y = \"\""), (17, 6), "empty expression"),
        // division by a parameter that can be 0
        (
            edit("v/k", "k*v/a"),
            (14, 29),
            "division by the parameter a, which may be 0",
        ),
        (edit("v/k", "k*v/0"), (14, 29), "division by zero"),
        // undefined state
        (
            edit("x = \"x + dt*v\"", "z = \"x + dt*v\""),
            (13, 5),
            "not a state",
        ),
        (
            edit("[observation]\ny = \"x\"", "[observation]"),
            (16, 1),
            "no entry for the output y",
        ),
        // NaN at the start
        (edit("y = \"x\"", "y = \"log(x)\""), (17, 6), "yields -inf"),
        (
            edit("y = \"x\"", "y = \"sqrt(x - 1)\""),
            (17, 6),
            "yields NaN",
        ),
        // parameters
        (
            edit("dt = 0.1", "dt = 0.1\nunused = { value = 1 }"),
            (11, 10),
            "appears in no equation",
        ),
        (
            edit(
                "k = { value = 2.0, min = 0 }",
                "k = { value = -2.0, min = 0 }",
            ),
            (8, 5),
            "outside its bounds",
        ),
        (
            edit(
                "k = { value = 2.0, min = 0 }",
                "k = { value = 2.0, min = 1 }",
            ),
            (8, 5),
            "give both min and max",
        ),
        (
            edit("q = { value = 0.1, min = 0 }", "q = { value = -0.1 }"),
            (9, 5),
            "variance; its value must be positive",
        ),
        // names
        (
            edit("states = [\"x\", \"v\"]", "states = [\"x\", \"t\"]"),
            (2, 16),
            "reserved",
        ),
        (
            edit("inputs = [\"u\"]", "inputs = [\"x\"]"),
            (3, 11),
            "both a state and a input",
        ),
        (
            edit("states = [\"x\", \"v\"]", "states = []"),
            (2, 10),
            "at least one state",
        ),
        // variances
        (
            edit("x = \"q\"", "x = \"q*x\""),
            (20, 8),
            "only on parameters",
        ),
        (edit("y = 0.5", "y = -0.5"), (22, 5), "must be positive"),
        (
            edit(
                "x = { mean = 0, variance = 1 }",
                "x = { mean = 0, variance = \"-1\" }",
            ),
            (25, 29),
            "initial variance of x is -1",
        ),
        (
            edit("[parameters]", "[parameters]\nbad = \"text\""),
            (7, 7),
            "expected a number (fixed) or a table",
        ),
        // priors, checked when read (not first by pmmh)
        (
            edit(
                "a = { value = 0.5 }",
                "a = { value = 0.5, prior = { family = \"normal\", mean = 0.0, sd = -1.0 } }",
            ),
            (7, 5),
            "parameter a: prior:",
        ),
        (
            edit(
                "a = { value = 0.5 }",
                "a = { value = 0.5, prior = { family = \"gamma\", shape = 0.0, rate = 1.0 } }",
            ),
            (7, 5),
            "parameter a: prior:",
        ),
        (
            edit(
                "a = { value = 0.5 }",
                "a = { value = 0.5, prior = { family = \"uniform\", low = 1.0, high = 0.0 } }",
            ),
            (7, 5),
            "parameter a: prior:",
        ),
        (
            edit(
                "a = { value = 0.5 }",
                "a = { value = 0.5, prior = { family = \"normal\", mean = nan, sd = 1.0 } }",
            ),
            (7, 5),
            "parameter a: prior:",
        ),
        (
            edit(
                "a = { value = 0.5 }",
                "a = { value = 0.5, prior = { family = \"beta\", a = 2.0, b = 2.0 } }",
            ),
            (7, 5),
            "give it min = 0, max = 1",
        ),
        (
            edit(
                "a = { value = 0.5 }",
                "a = { value = -0.5, prior = { family = \"gamma\", shape = 2.0, rate = 1.0 } }",
            ),
            (7, 5),
            "no mass at the value -0.5",
        ),
    ];
    assert!(cases.len() >= 15);
    let mut wrong = Vec::new();
    for (text, (line, column), words) in &cases {
        let Err(e) = ModelFile::parse(text, "m.toml") else {
            wrong.push(format!("accepted ({words})"));
            continue;
        };
        let shown = e.to_string();
        let prefix = format!("m.toml:{line}:{column}: ");
        if shown.contains('\n') || !shown.contains(words) || !shown.starts_with(&prefix) {
            wrong.push(format!("expected {prefix}...{words}..., got {shown}"));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// Stable-Rust stand-in for the `model_toml` fuzz target: thousands of random edits of
/// a valid file (characters deleted, inserted, replaced, lines swapped) never panic,
/// and every refusal is one line with a line and column inside the text.
#[test]
fn random_edits_never_panic_and_errors_stay_on_one_line_inside_the_file() {
    use rand::RngExt;
    let alphabet: Vec<char> = "xvatqkdu0123456789.+-*/^()=,[]{}\"' \n#_eEsinlogexpmaxy"
        .chars()
        .collect();
    let mut rng = sysid_smc::stream(35, 0);
    let mut refused = 0;
    for _ in 0..3000 {
        let mut text: Vec<char> = GOOD.chars().collect();
        for _ in 0..rng.random_range(1..4) {
            let at = rng.random_range(0..text.len());
            match rng.random_range(0..3) {
                0 => {
                    text.remove(at);
                }
                1 => text.insert(at, alphabet[rng.random_range(0..alphabet.len())]),
                _ => text[at] = alphabet[rng.random_range(0..alphabet.len())],
            }
        }
        let text: String = text.into_iter().collect();
        match ModelFile::parse(&text, "m.toml") {
            Ok(model) => {
                // a valid model builds and simulates (or says why not)
                if let Ok(smc) = model.at(&model.free_values()) {
                    let inputs = vec![0.0; 5 * smc.input_dim()];
                    let _ = smc.simulate(5, &inputs, 1);
                }
            }
            Err(e) => {
                refused += 1;
                let lines = text.lines().count().max(1);
                assert!(!e.message.contains('\n'), "{e}");
                assert!(e.line >= 1 && e.line <= lines + 1, "{e}\n{text}");
                assert!(e.column >= 1, "{e}");
            }
        }
    }
    assert!(
        refused > 1000,
        "{refused} refused: the edits should break most files"
    );
}

/// Every TOML block of the docs is a valid model file (the guide's is the shipped
/// example, word for word).
#[test]
fn the_model_files_shown_in_the_docs_are_valid() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut blocks = 0;
    for doc in ["docs/guide.md", "docs/model-format.md"] {
        let text = std::fs::read_to_string(root.join(doc)).unwrap();
        for block in text.split("```toml\n").skip(1) {
            let body = block.split("```").next().unwrap();
            ModelFile::parse(body, doc).unwrap_or_else(|e| panic!("{e}\n{body}"));
            blocks += 1;
        }
    }
    assert!(blocks >= 2);
    let guide = std::fs::read_to_string(root.join("docs/guide.md")).unwrap();
    let example = std::fs::read_to_string(root.join("examples/models/oscillator.toml")).unwrap();
    let body: String = example
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(
        guide.contains(&body),
        "the guide shows examples/models/oscillator.toml"
    );
}
