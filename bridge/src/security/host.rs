//! Host names: the one identity a fleet host has, shared by its certificate, its file names
//! and the access-control subjects.

use std::fmt;

/// Why a host (or fleet) name was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HostNameError {
    /// Empty or longer than [`HostName::MAX_LEN`].
    #[error("host name must be 1 to {max} characters, got {0}", max = HostName::MAX_LEN)]
    Length(usize),
    /// A character other than ASCII letters, digits, '-' and '_'.
    #[error("host name may hold only ASCII letters, digits, '-' and '_', got {0:?}")]
    Character(char),
    /// The name of a file the fleet directory already uses (`ca` would overwrite the
    /// authority's `ca.pem` and `ca.key`).
    #[error("host name {0:?} is reserved (it names the fleet authority's files)")]
    Reserved(String),
}

/// The validated name of a fleet host, e.g. `world` or `h1`.
///
/// It is the Common Name of the host's certificate, the stem of its files (`{name}.pem`,
/// `{name}.key`) and the subject the access control matches. The character set keeps it a
/// safe file name and a single key-expression chunk, and, having no dot, it can never equal
/// the Common Name of a certificate a public web authority issues (always a domain name).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct HostName(String);

impl HostName {
    /// Longest accepted name.
    pub const MAX_LEN: usize = 40;

    /// Validates a host name.
    pub fn new(name: &str) -> Result<Self, HostNameError> {
        check_name(name)?;
        if name.eq_ignore_ascii_case("ca") {
            return Err(HostNameError::Reserved(name.to_owned()));
        }
        Ok(Self(name.to_owned()))
    }

    /// The name as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Whether the name is also a valid DNS label (no '_', no leading or trailing '-'), so it
    /// can be a DNS subject alternative name of the host's certificate.
    pub(crate) fn is_dns_label(&self) -> bool {
        !self.0.contains('_') && !self.0.starts_with('-') && !self.0.ends_with('-')
    }
}

/// The character and length rules of host names, also applied to fleet names.
pub(crate) fn check_name(name: &str) -> Result<(), HostNameError> {
    if name.is_empty() || name.len() > HostName::MAX_LEN {
        return Err(HostNameError::Length(name.len()));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        return Err(HostNameError::Character(c));
    }
    Ok(())
}

impl fmt::Display for HostName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl AsRef<str> for HostName {
    fn as_ref(&self) -> &str {
        &self.0
    }
}

impl std::str::FromStr for HostName {
    type Err = HostNameError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::new(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_letters_digits_dash_underscore() {
        for name in ["world", "h1", "agent-7", "lab_host_2", &"x".repeat(40)] {
            assert_eq!(
                HostName::new(name).map(|h| h.to_string()),
                Ok(name.to_owned())
            );
        }
    }

    #[test]
    fn refuses_bad_names_with_the_reason() {
        assert_eq!(HostName::new(""), Err(HostNameError::Length(0)));
        assert_eq!(
            HostName::new(&"x".repeat(41)),
            Err(HostNameError::Length(41))
        );
        assert_eq!(HostName::new("h1.lab"), Err(HostNameError::Character('.')));
        assert_eq!(HostName::new("../etc"), Err(HostNameError::Character('.')));
        assert_eq!(HostName::new("a/b"), Err(HostNameError::Character('/')));
        assert_eq!(HostName::new("h*"), Err(HostNameError::Character('*')));
        assert_eq!(HostName::new("hé"), Err(HostNameError::Character('é')));
        assert_eq!(
            HostName::new("CA"),
            Err(HostNameError::Reserved("CA".to_owned()))
        );
    }

    #[test]
    fn dns_label_excludes_underscore_and_edge_dashes() {
        let label = |s| HostName::new(s).map(|h| h.is_dns_label());
        assert_eq!(label("h-1"), Ok(true));
        assert_eq!(label("h_1"), Ok(false));
        assert_eq!(label("-h"), Ok(false));
        assert_eq!(label("h-"), Ok(false));
    }
}
