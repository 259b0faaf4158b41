//! The one catalogue of built-in system names: what each is and which commands take
//! it, so that every command resolves `--system` (or `simulate NAME`) the same way
//! and lists the same names when one is unknown.

use crate::error::CliError;

/// A built-in system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum System {
    /// The scalar linear Gaussian model (phi, q, r).
    Lgss,
    /// The two-input, two-output linear system of seed 004.
    Lti2x2,
    /// The nonlinear benchmark of seed 000 (hand-tuned code; also a model file).
    Nlbench,
    /// The blind Wiener system of seed 001.
    Wiener,
    /// The driven pendulum (a model file; needs a torque input).
    Pendulum,
}

/// What a command does with a system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Use {
    /// `sysid simulate NAME`.
    Simulate,
    /// `pf`, `psmooth`, `pmmh`, `pgas` with `--system NAME`.
    Particle,
}

/// Name, system, and the uses it supports.
const CATALOGUE: [(&str, System, &[Use]); 5] = [
    ("lgss", System::Lgss, &[Use::Simulate, Use::Particle]),
    ("lti2x2", System::Lti2x2, &[Use::Simulate]),
    ("nlbench", System::Nlbench, &[Use::Simulate, Use::Particle]),
    ("wiener", System::Wiener, &[Use::Simulate]),
    ("pendulum", System::Pendulum, &[Use::Particle]),
];

/// The names that support `usage`, comma separated.
pub fn known(usage: Use) -> String {
    CATALOGUE
        .iter()
        .filter(|(_, _, uses)| uses.contains(&usage))
        .map(|(name, _, _)| *name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The system called `name`, if it supports `usage`; otherwise the error lists the
/// names that do.
pub fn lookup(name: &str, usage: Use) -> Result<System, CliError> {
    CATALOGUE
        .iter()
        .find(|(n, _, uses)| *n == name && uses.contains(&usage))
        .map(|(_, system, _)| *system)
        .ok_or_else(|| CliError::UnknownSystem {
            name: name.to_string(),
            known: known(usage),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every name of the model-file catalogue is known to the particle commands, and
    /// the linear ones to `sysid_models::System`.
    #[test]
    fn the_catalogue_agrees_with_the_libraries() {
        for name in sysid::modelfile::builtin::names() {
            assert!(lookup(name, Use::Particle).is_ok(), "{name}");
        }
        for s in sysid::models::System::ALL {
            assert!(lookup(s.name(), Use::Simulate).is_ok(), "{}", s.name());
        }
        assert!(lookup("lti2x2", Use::Particle).is_err());
        assert_eq!(known(Use::Particle), "lgss, nlbench, pendulum");
    }
}
