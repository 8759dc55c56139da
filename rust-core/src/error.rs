//! The one error type: a message a user can act on, naming the bad parameter.

use std::fmt;

#[derive(Clone, Debug, PartialEq)]
pub struct StamError {
    pub message: String,
    /// For an unknown key, the same as data: a host that reads keys of its
    /// own (a renderer's frame parameters) completes the message with them
    /// (`with_host_keys`).
    pub unknown_key: Option<UnknownKey>,
}

/// A key no reader of the surface accepts.
#[derive(Clone, Debug, PartialEq)]
pub struct UnknownKey {
    pub key: String,
    pub surface: String,
    /// Every key the surface accepts, the material's first.
    pub accepted: Vec<String>,
}

impl UnknownKey {
    /// "unknown parameter 'key' for surface 's' (accepted: a, b, ...)",
    /// with "; did you mean 'x'?" for the accepted key closest to it within
    /// two edits (or to it with "_um" added: a forgotten unit suffix).
    pub fn message(&self) -> String {
        let mut m = format!(
            "unknown parameter '{}' for surface '{}' (accepted: {})",
            self.key,
            self.surface,
            self.accepted.join(", ")
        );
        let distance = |c: &String| {
            strsim::levenshtein(&self.key, c)
                .min(strsim::levenshtein(&(self.key.clone() + "_um"), c))
        };
        if let Some((_, best)) = self
            .accepted
            .iter()
            .map(|c| (distance(c), c))
            .filter(|&(d, _)| d <= 2)
            .min_by_key(|&(d, _)| d)
        {
            m += &format!("; did you mean '{best}'?");
        }
        m
    }
}

impl StamError {
    pub fn new(message: impl Into<String>) -> Self {
        StamError {
            message: message.into(),
            unknown_key: None,
        }
    }

    /// The error of an unknown key, its message from the data.
    pub fn unknown_key(unknown: UnknownKey) -> Self {
        StamError {
            message: unknown.message(),
            unknown_key: Some(unknown),
        }
    }

    /// For an unknown key: the message with the host's own keys among the
    /// accepted ones (each once) and the suggestion taken over all of them.
    /// Other errors unchanged.
    pub fn with_host_keys(self, host_keys: &[String]) -> Self {
        match self.unknown_key {
            Some(mut u) => {
                for k in host_keys {
                    if !u.accepted.contains(k) {
                        u.accepted.push(k.clone());
                    }
                }
                StamError::unknown_key(u)
            }
            None => self,
        }
    }
}

impl fmt::Display for StamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for StamError {}

#[cfg(test)]
mod tests {
    use super::*;

    fn unknown(key: &str) -> StamError {
        StamError::unknown_key(UnknownKey {
            key: key.into(),
            surface: "cd".into(),
            accepted: vec!["surface".into(), "period_um".into(), "twist_axis".into()],
        })
    }

    #[test]
    fn an_unknown_key_names_the_closest_accepted_one_and_the_hosts() {
        let m = unknown("perod_um").message;
        assert!(m.starts_with("unknown parameter 'perod_um' for surface 'cd' (accepted: surface, period_um, twist_axis)"), "{m}");
        assert!(m.ends_with("; did you mean 'period_um'?"), "{m}");
        // A forgotten unit suffix is no edit.
        assert!(unknown("period")
            .message
            .ends_with("did you mean 'period_um'?"));
        // Three edits away from everything: no suggestion.
        assert!(!unknown("quux").message.contains("did you mean"));
        // The host's keys join the list once, and the suggestion.
        let e = unknown("twistt").with_host_keys(&["twist".into(), "surface".into()]);
        assert!(
            e.message
                .contains("(accepted: surface, period_um, twist_axis, twist)"),
            "{}",
            e.message
        );
        assert!(
            e.message.ends_with("did you mean 'twist'?"),
            "{}",
            e.message
        );
        // Other errors are left as they are.
        let other = StamError::new("parameter 'x' must be positive");
        assert_eq!(other.clone().with_host_keys(&["twist".into()]), other);
    }
}
