//! The fleet's certificate authority and the host certificates it issues, made with rcgen.

use std::fmt;
use std::time::Duration;

use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose, SanType,
};
use x509_parser::certificate::X509Certificate;
use x509_parser::prelude::FromDer;

use super::host::{HostName, HostNameError, check_name};

/// How long a fleet authority's certificate is valid, from its creation.
pub const CA_VALIDITY_DAYS: u32 = 3650;
/// How long a host certificate is valid, from its issue (never past the authority's own end).
pub const HOST_VALIDITY_DAYS: u32 = 730;
/// Subject alternative names every host certificate carries, so hosts simulated on one
/// machine connect to each other by `localhost` or `127.0.0.1`.
pub const DEFAULT_SANS: [&str; 2] = ["localhost", "127.0.0.1"];

/// Certificates are valid from a little before their creation, so a host whose clock is a few
/// minutes late does not refuse a brand-new certificate.
const CLOCK_SKEW: Duration = Duration::from_secs(3600);
const DAY: Duration = Duration::from_secs(86_400);

/// Why an authority could not be created or loaded, or a host certificate not issued.
#[derive(Debug, thiserror::Error)]
pub enum AuthorityError {
    /// The fleet name breaks the host-name rules.
    #[error("invalid fleet name: {0}")]
    FleetName(HostNameError),
    /// A subject alternative name is neither an IP address nor an ASCII DNS name.
    #[error("invalid subject alternative name {san:?}: {reason}")]
    San {
        /// The name as given.
        san: String,
        /// What rcgen said about it.
        reason: String,
    },
    /// rcgen could not generate a key or sign a certificate.
    #[error("cannot make a certificate: {0}")]
    Rcgen(#[from] rcgen::Error),
    /// The authority's certificate is not a PEM X.509 certificate.
    #[error("the authority certificate is not a PEM X.509 certificate: {0}")]
    CaCertificate(String),
    /// The authority's certificate is not one this module makes: not a CA, or its subject is
    /// not a single Common Name.
    #[error("the authority certificate is not a setfleet fleet authority: {0}")]
    NotAFleetAuthority(&'static str),
    /// The authority's key is not a PEM PKCS#8 private key.
    #[error("the authority key is not a PEM private key: {0}")]
    CaKey(rcgen::Error),
    /// The authority's key does not belong to its certificate.
    #[error("the authority key does not match the authority certificate")]
    KeyMismatch,
}

/// A host's certificate and private key, issued by a [`FleetAuthority`].
///
/// The certificate's Common Name is the host name: the access control knows the host by it.
/// `key_pem` is a secret (PKCS#8 PEM): it is left out of `Debug`.
#[derive(Clone)]
pub struct HostIdentity {
    /// The host, also the certificate's Common Name.
    pub name: HostName,
    /// The certificate, PEM.
    pub cert_pem: String,
    /// The private key, PKCS#8 PEM. Secret.
    pub key_pem: String,
}

impl fmt::Debug for HostIdentity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("HostIdentity")
            .field("name", &self.name)
            .field("cert_pem", &self.cert_pem)
            .field("key_pem", &"<secret>")
            .finish()
    }
}

/// The fleet's certificate authority: a self-signed CA whose certificate every host trusts
/// and whose key signs the host certificates.
///
/// Its key is the fleet's master secret: whoever holds it can make a certificate for any host
/// name, so any role. Keep `ca.key` on the machine that makes certificates only.
pub struct FleetAuthority {
    issuer: Issuer<'static, KeyPair>,
    cert_pem: String,
    not_after: time::OffsetDateTime,
}

impl fmt::Debug for FleetAuthority {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FleetAuthority")
            .field("cert_pem", &self.cert_pem)
            .field("key", &"<secret>")
            .finish()
    }
}

impl FleetAuthority {
    /// Makes a new authority (ECDSA P-256 key, certificate valid [`CA_VALIDITY_DAYS`] days,
    /// allowed to sign host certificates only: path length 0). Its Common Name is
    /// `{fleet_name} fleet CA`; `fleet_name` follows the host-name rules.
    pub fn generate(fleet_name: &str) -> Result<Self, AuthorityError> {
        check_name(fleet_name).map_err(AuthorityError::FleetName)?;
        let key = KeyPair::generate()?;
        let now = time::OffsetDateTime::now_utc();
        let mut params = ca_params(&format!("{fleet_name} fleet CA"));
        params.not_before = now - CLOCK_SKEW;
        params.not_after = now + DAY * CA_VALIDITY_DAYS;
        let cert_pem = params.self_signed(&key)?.pem();
        let not_after = params.not_after;
        Ok(Self {
            issuer: Issuer::new(params, key),
            cert_pem,
            not_after,
        })
    }

    /// Loads an authority from its certificate and key (the contents of `ca.pem` and
    /// `ca.key`), to issue more host certificates later.
    pub fn from_pem(cert_pem: &str, key_pem: &str) -> Result<Self, AuthorityError> {
        let (_, pem) = x509_parser::pem::parse_x509_pem(cert_pem.as_bytes())
            .map_err(|e| AuthorityError::CaCertificate(e.to_string()))?;
        if pem.label != "CERTIFICATE" {
            return Err(AuthorityError::CaCertificate(format!(
                "a PEM {:?} block instead of a certificate",
                pem.label
            )));
        }
        let (_, cert) = X509Certificate::from_der(&pem.contents)
            .map_err(|e| AuthorityError::CaCertificate(e.to_string()))?;
        if !cert.is_ca() {
            return Err(AuthorityError::NotAFleetAuthority("it is not a CA"));
        }
        let subject = cert.subject();
        if subject.iter_attributes().count() != 1 {
            return Err(AuthorityError::NotAFleetAuthority(
                "its subject is not a single Common Name",
            ));
        }
        let common_name = subject
            .iter_common_name()
            .next()
            .and_then(|cn| cn.as_str().ok())
            .ok_or(AuthorityError::NotAFleetAuthority(
                "its subject is not a single Common Name",
            ))?;
        let key = KeyPair::from_pem(key_pem).map_err(AuthorityError::CaKey)?;
        if cert.public_key().subject_public_key.data.as_ref() != key.public_key_raw() {
            return Err(AuthorityError::KeyMismatch);
        }
        // Signing needs the authority's subject, key usages and key; the subject is rebuilt
        // from the one Common Name, which rcgen encodes exactly as it did when it made the
        // certificate, so issued certificates name their issuer byte for byte.
        let params = ca_params(common_name);
        Ok(Self {
            issuer: Issuer::new(params, key),
            cert_pem: cert_pem.to_owned(),
            not_after: cert.validity().not_after.to_datetime(),
        })
    }

    /// The authority's certificate, PEM: every host's trust anchor (`ca.pem`). Public.
    pub fn cert_pem(&self) -> &str {
        &self.cert_pem
    }

    /// The authority's private key, PKCS#8 PEM (`ca.key`). Secret.
    pub fn key_pem(&self) -> String {
        self.issuer.key().serialize_pem()
    }

    /// Issues a certificate for `host` with a fresh ECDSA P-256 key.
    ///
    /// Common Name: the host name. Subject alternative names: [`DEFAULT_SANS`], the host name
    /// when it is a valid DNS label, then `extra_sans` (IP addresses or DNS names the other
    /// hosts use to reach this one; a connecting host checks the name it dialled against
    /// them). Usable as a TLS server and client certificate, since every host both listens and
    /// connects. Valid [`HOST_VALIDITY_DAYS`] days, never past the authority's own end.
    pub fn issue_host(
        &self,
        host: &HostName,
        extra_sans: &[String],
    ) -> Result<HostIdentity, AuthorityError> {
        let mut names: Vec<String> = DEFAULT_SANS.iter().map(|s| (*s).to_owned()).collect();
        if host.is_dns_label() {
            names.push(host.as_str().to_owned());
        }
        for san in extra_sans {
            let san = san.trim();
            if san.is_empty() {
                return Err(AuthorityError::San {
                    san: san.to_owned(),
                    reason: "empty".to_owned(),
                });
            }
            if !names.iter().any(|n| n.eq_ignore_ascii_case(san)) {
                names.push(san.to_owned());
            }
        }
        let mut subject_alt_names = Vec::with_capacity(names.len());
        for name in names {
            subject_alt_names.push(san(&name)?);
        }

        let now = time::OffsetDateTime::now_utc();
        let mut params = CertificateParams::default();
        params.distinguished_name = DistinguishedName::new();
        params
            .distinguished_name
            .push(DnType::CommonName, host.as_str());
        params.subject_alt_names = subject_alt_names;
        params.is_ca = IsCa::ExplicitNoCa;
        params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        params.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        params.use_authority_key_identifier_extension = true;
        params.not_before = now - CLOCK_SKEW;
        params.not_after = (now + DAY * HOST_VALIDITY_DAYS).min(self.not_after);

        let key = KeyPair::generate()?;
        let cert = params.signed_by(&key, &self.issuer)?;
        Ok(HostIdentity {
            name: host.clone(),
            cert_pem: cert.pem(),
            key_pem: key.serialize_pem(),
        })
    }
}

/// The parameters of an authority certificate with this Common Name.
fn ca_params(common_name: &str) -> CertificateParams {
    let mut params = CertificateParams::default();
    params.distinguished_name = DistinguishedName::new();
    params
        .distinguished_name
        .push(DnType::CommonName, common_name);
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::CrlSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    params
}

/// One subject alternative name: an IP address if it parses as one, else a DNS name.
fn san(name: &str) -> Result<SanType, AuthorityError> {
    let invalid = |reason: String| AuthorityError::San {
        san: name.to_owned(),
        reason,
    };
    if let Ok(ip) = name.parse() {
        return Ok(SanType::IpAddress(ip));
    }
    if name.contains('*') {
        return Err(invalid("wildcard names are not issued".to_owned()));
    }
    let dns = name
        .try_into()
        .map_err(|e: rcgen::Error| invalid(e.to_string()))?;
    Ok(SanType::DnsName(dns))
}

#[cfg(test)]
mod tests {
    use x509_parser::extensions::GeneralName;

    use super::*;

    fn parse(pem: &str) -> (Vec<u8>, x509_parser::pem::Pem) {
        let (_, pem) = x509_parser::pem::parse_x509_pem(pem.as_bytes()).unwrap();
        (pem.contents.clone(), pem)
    }

    fn host(name: &str) -> HostName {
        HostName::new(name).unwrap()
    }

    #[test]
    fn authority_is_a_ca_that_signs_end_entities_only() {
        let ca = FleetAuthority::generate("lab").unwrap();
        let (der, _) = parse(ca.cert_pem());
        let (_, cert) = X509Certificate::from_der(&der).unwrap();
        assert!(cert.is_ca());
        let cn = cert.subject().iter_common_name().next().unwrap();
        assert_eq!(cn.as_str().unwrap(), "lab fleet CA");
        let constraints = cert.basic_constraints().unwrap().unwrap().value;
        assert_eq!(constraints.path_len_constraint, Some(0));
        let usage = cert.key_usage().unwrap().unwrap().value;
        assert!(usage.key_cert_sign());
    }

    #[test]
    fn host_certificate_names_the_host_and_its_addresses() {
        let ca = FleetAuthority::generate("lab").unwrap();
        let id = ca
            .issue_host(&host("h1"), &["10.0.0.7".to_owned(), "h1.lab".to_owned()])
            .unwrap();
        assert_eq!(id.name.as_str(), "h1");
        let (der, _) = parse(&id.cert_pem);
        let (_, cert) = X509Certificate::from_der(&der).unwrap();
        let (ca_der, _) = parse(ca.cert_pem());
        let (_, ca_cert) = X509Certificate::from_der(&ca_der).unwrap();

        assert!(!cert.is_ca());
        assert_eq!(cert.issuer().as_raw(), ca_cert.subject().as_raw());
        let cn = cert.subject().iter_common_name().next().unwrap();
        assert_eq!(cn.as_str().unwrap(), "h1");
        let sans = &cert.subject_alternative_name().unwrap().unwrap().value;
        let names: Vec<String> = sans
            .general_names
            .iter()
            .map(|n| match n {
                GeneralName::DNSName(d) => d.to_string(),
                GeneralName::IPAddress(ip) => {
                    ip.iter().map(u8::to_string).collect::<Vec<_>>().join(".")
                }
                other => format!("{other:?}"),
            })
            .collect();
        assert_eq!(
            names,
            ["localhost", "127.0.0.1", "h1", "10.0.0.7", "h1.lab"]
        );
        let eku = cert.extended_key_usage().unwrap().unwrap().value;
        assert!(eku.server_auth && eku.client_auth);
        assert!(cert.validity().not_after <= ca_cert.validity().not_after);
        assert!(id.key_pem.starts_with("-----BEGIN PRIVATE KEY-----"));
        assert!(!format!("{id:?}").contains("PRIVATE KEY"));
    }

    #[test]
    fn host_name_is_a_san_only_when_a_dns_label() {
        let ca = FleetAuthority::generate("lab").unwrap();
        let id = ca.issue_host(&host("agent_1"), &[]).unwrap();
        let (der, _) = parse(&id.cert_pem);
        let (_, cert) = X509Certificate::from_der(&der).unwrap();
        let sans = &cert.subject_alternative_name().unwrap().unwrap().value;
        assert_eq!(sans.general_names.len(), DEFAULT_SANS.len());
    }

    #[test]
    fn refuses_bad_sans_and_fleet_names() {
        let ca = FleetAuthority::generate("lab").unwrap();
        for bad in ["", "*.lab", "héhé.lab"] {
            let err = ca.issue_host(&host("h1"), &[bad.to_owned()]).unwrap_err();
            assert!(matches!(err, AuthorityError::San { .. }), "{bad:?}: {err}");
        }
        assert!(matches!(
            FleetAuthority::generate("my fleet"),
            Err(AuthorityError::FleetName(HostNameError::Character(' ')))
        ));
    }

    #[test]
    fn reloaded_authority_issues_certificates_under_the_same_subject() {
        let ca = FleetAuthority::generate("lab").unwrap();
        let again = FleetAuthority::from_pem(ca.cert_pem(), &ca.key_pem()).unwrap();
        let id = again.issue_host(&host("h9"), &[]).unwrap();
        let (der, _) = parse(&id.cert_pem);
        let (_, cert) = X509Certificate::from_der(&der).unwrap();
        let (ca_der, _) = parse(ca.cert_pem());
        let (_, ca_cert) = X509Certificate::from_der(&ca_der).unwrap();
        assert_eq!(cert.issuer().as_raw(), ca_cert.subject().as_raw());
        assert!(cert.validity().not_after <= ca_cert.validity().not_after);
        assert!(!format!("{again:?}").contains("PRIVATE KEY"));
    }

    #[test]
    fn loading_refuses_a_foreign_key_or_a_host_certificate() {
        let ca = FleetAuthority::generate("lab").unwrap();
        let other = FleetAuthority::generate("other").unwrap();
        assert!(matches!(
            FleetAuthority::from_pem(ca.cert_pem(), &other.key_pem()),
            Err(AuthorityError::KeyMismatch)
        ));
        let id = ca.issue_host(&host("h1"), &[]).unwrap();
        assert!(matches!(
            FleetAuthority::from_pem(&id.cert_pem, &id.key_pem),
            Err(AuthorityError::NotAFleetAuthority(_))
        ));
        assert!(matches!(
            FleetAuthority::from_pem(&ca.key_pem(), &ca.key_pem()),
            Err(AuthorityError::CaCertificate(_))
        ));
        assert!(matches!(
            FleetAuthority::from_pem(ca.cert_pem(), "not a key"),
            Err(AuthorityError::CaKey(_))
        ));
    }
}
