//! Inputs that look odd but are valid must give exactly the plain input's result: a
//! byte-order mark, CRLF line endings, quoted and padded fields, the spellings of a
//! missing output, and an unstable model (no sysid command requires a stable A:
//! filters, smoothers and EM are defined for unstable systems).

use super::common::{json_of, s, scratch_dir, sysid};

const MODEL: &str = r#"{"a": [[0.9]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#;

fn loglik(model: &str, data: &[u8]) -> f64 {
    let dir = scratch_dir();
    std::fs::write(dir.join("m.json"), model).unwrap();
    std::fs::write(dir.join("d.csv"), data).unwrap();
    let out = sysid(&[
        "loglik",
        "--model",
        s(&dir.join("m.json")),
        "--data",
        s(&dir.join("d.csv")),
        "--json",
    ]);
    json_of(&out)["loglik"].as_f64().unwrap()
}

#[test]
fn awkward_but_valid_files_read_as_the_plain_ones() {
    let plain = loglik(MODEL, b"t,y1\n1,0.5\n2,-0.25\n3,\n4,0.75\n");
    for (what, data) in [
        (
            "byte-order mark",
            &b"\xef\xbb\xbft,y1\n1,0.5\n2,-0.25\n3,\n4,0.75\n"[..],
        ),
        ("CRLF", b"t,y1\r\n1,0.5\r\n2,-0.25\r\n3,\r\n4,0.75\r\n"),
        (
            "BOM and CRLF",
            b"\xef\xbb\xbft,y1\r\n1,0.5\r\n2,-0.25\r\n3,\r\n4,0.75\r\n",
        ),
        (
            "quoted fields",
            b"\"t\",\"y1\"\n\"1\",\"0.5\"\n2,-0.25\n3,\"\"\n4,0.75\n",
        ),
        (
            "padded fields",
            b"t , y1\n1,  0.5\n2 ,-0.25\n3,\n4,0.75  \n",
        ),
        ("NaN for missing", b"t,y1\n1,0.5\n2,-0.25\n3,NaN\n4,0.75\n"),
        ("NA for missing", b"t,y1\n1,0.5\n2,-0.25\n3,NA\n4,0.75\n"),
        ("blank lines", b"t,y1\n1,0.5\n\n2,-0.25\n3,\n4,0.75\n\n"),
        ("no final newline", b"t,y1\n1,0.5\n2,-0.25\n3,\n4,0.75"),
    ] {
        assert_eq!(loglik(MODEL, data).to_bits(), plain.to_bits(), "{what}");
    }
    // columns in another order, and without t
    assert_eq!(
        loglik(MODEL, b"y1,t\n0.5,1\n-0.25,2\n,3\n0.75,4\n").to_bits(),
        plain.to_bits()
    );
    assert_eq!(
        // a one-column file: blank lines are skipped, so a missing value is NaN or NA
        loglik(MODEL, b"y1\n0.5\n-0.25\nNA\n0.75\n").to_bits(),
        plain.to_bits()
    );
}

#[test]
fn an_unstable_model_is_filtered_and_smoothed() {
    let unstable = r#"{"a": [[1.5]], "c": [[1.0]], "q": [[1.0]], "r": [[0.5]]}"#;
    let l = loglik(unstable, b"t,y1\n1,0.5\n2,1.0\n3,1.4\n4,2.2\n5,3.1\n");
    assert!(l.is_finite(), "{l}");
}
