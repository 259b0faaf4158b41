//! `sysid fit`: one file per model class (`lti`, `affine` for nlbench and affine
//! model files, `model` for model files, `wiener`), the options they share, and the
//! dispatch. The classes do not import each other, except `model`, which hands an
//! affine model file to `affine`.

mod affine;
mod fix;
mod lti;
mod model;
mod options;
mod toml_metadata;
mod wiener;

pub use options::Options;

use crate::error::CliError;

/// `sysid fit`: refuses the outputs that exist and the options of another class,
/// then runs the class's command.
pub fn run(o: &Options) -> Result<(), CliError> {
    // refuse before a long fit, not after it
    crate::files::refuse_existing(
        std::iter::once(o.out.as_path()).chain(o.trace.as_deref()),
        o.force,
    )?;
    let Some(kind) = &o.kind else {
        options::refuse_other_class_options(o, "model")?;
        return model::run(o);
    };
    let class = kind.to_ascii_lowercase();
    if ["lti", "nlbench", "affine", "wiener"].contains(&class.as_str()) {
        options::refuse_other_class_options(o, &class)?;
    }
    match class.as_str() {
        "lti" => {}
        "nlbench" => return affine::run(o, true),
        "wiener" => return wiener::run(o),
        "affine" => {
            return match o.system.as_deref() {
                None => affine::run(o, false),
                Some("nlbench") => affine::run(o, true),
                Some(other) => Err(CliError::UnknownSystem {
                    name: other.into(),
                    known: "nlbench (or give a linear model with --init FILE)".into(),
                }),
            };
        }
        _ => {
            return Err(CliError::BadOption {
                option: "fit",
                message: format!(
                    "unknown model class {kind:?} (known: lti, nlbench, affine, wiener; or \
                     give a model file with --model)"
                ),
            });
        }
    }
    lti::run(o)
}
