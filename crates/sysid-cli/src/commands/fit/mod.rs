//! `sysid fit`: one file per model class (`lti`, `affine` for nlbench and affine
//! model files, `model` for model files, `wiener`), their command lines (`args`), the
//! options they share, and the dispatch. The classes do not import each other, except `model`, which hands an
//! affine model file to `affine`.

mod affine;
mod args;
mod fix;
mod lti;
mod model;
mod options;
mod toml_metadata;
mod wiener;

pub use args::FitCommand;
pub use options::Options;

use crate::error::CliError;

/// `sysid fit`: refuses the outputs that exist, then runs the class's command.
pub fn run(command: FitCommand) -> Result<(), CliError> {
    let options = match command.class {
        Some(class) => Some(Options::of_class(class, command.given)),
        None => Options::of_model_file(command),
    };
    let Some(o) = options else {
        return Err(CliError::BadOption {
            option: "fit",
            message: "give a model class (lti, nlbench, affine, wiener) or a model file \
                      (--model m.toml)"
                .into(),
        });
    };
    // refuse before a long fit, not after it
    crate::files::check_outputs(
        std::iter::once(o.out.as_path()).chain(o.trace.as_deref()),
        o.force,
    )?;
    match o.kind.as_deref() {
        None => model::run(&o),
        Some("lti") => lti::run(&o),
        Some("nlbench") => affine::run(&o, true),
        Some("wiener") => wiener::run(&o),
        _ => match o.system.as_deref() {
            None => affine::run(&o, false),
            Some("nlbench") => affine::run(&o, true),
            Some(other) => Err(CliError::UnknownSystem {
                name: other.into(),
                known: "nlbench (or give a linear model with --init FILE)".into(),
            }),
        },
    }
}
