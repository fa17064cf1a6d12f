//! The fleet's certificate directory: writing a new fleet's files, adding a host later, and
//! finding and checking one host's files before a session uses them.
//!
//! ```text
//! DIR/ca.pem       the authority's certificate: every host needs it (public)
//! DIR/ca.key       the authority's key: only to issue more hosts (SECRET, mode 0600)
//! DIR/{host}.pem   the host's certificate (public)
//! DIR/{host}.key   the host's key: copy to that host only (SECRET, mode 0600)
//! ```

use std::fs::{self, DirBuilder, OpenOptions, Permissions};
use std::io::{self, Write};
use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

use super::authority::{AuthorityError, FleetAuthority, HostIdentity};
use super::host::{HostName, HostNameError};

/// File name of the authority's certificate.
pub const CA_CERT_FILE: &str = "ca.pem";
/// File name of the authority's private key.
pub const CA_KEY_FILE: &str = "ca.key";
/// Fleet name written into the authority's Common Name by [`write_fleet_certs`].
pub const FLEET_NAME: &str = "setfleet";

const SECRET_MODE: u32 = 0o600;
const PUBLIC_MODE: u32 = 0o644;
const DIR_MODE: u32 = 0o700;

/// Why a fleet's certificate files could not be written.
#[derive(Debug, thiserror::Error)]
pub enum CertWriteError {
    /// No host was asked for.
    #[error("no host given: name at least one host (e.g. world,h1,h2)")]
    NoHosts,
    /// A host name breaks the rules.
    #[error("invalid host name {name:?}: {source}")]
    HostName {
        /// The name as given.
        name: String,
        /// Which rule it breaks.
        source: HostNameError,
    },
    /// The same host was named twice (ignoring case: the files would collide on
    /// case-insensitive file systems).
    #[error("host {0:?} is named twice")]
    DuplicateHost(String),
    /// A file exists and overwriting was not asked for; nothing was written.
    #[error(
        "{} exists: refusing to overwrite the fleet's certificates (ask for overwrite to replace them)",
        .0.display()
    )]
    Exists(PathBuf),
    /// A file or the directory could not be read, created or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What the system said.
        source: io::Error,
    },
    /// A certificate could not be made, or the existing authority not loaded.
    #[error(transparent)]
    Authority(#[from] AuthorityError),
}

/// Why a host's TLS files are not usable.
#[derive(Debug, thiserror::Error)]
pub enum TlsFilesError {
    /// The file is missing or unreadable.
    #[error("cannot read {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: io::Error,
    },
    /// The file holds no PEM block of the expected kind.
    #[error("{} holds no PEM {expected}", path.display())]
    NotPem {
        /// The file.
        path: PathBuf,
        /// What it should hold: `certificate` or `private key`.
        expected: &'static str,
    },
    /// The private key file can be read by other users.
    #[error(
        "{} is readable by other users (mode {mode:03o}): it is a secret key; run `chmod 600` on it",
        path.display()
    )]
    KeyPermissions {
        /// The key file.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
    },
}

/// Where one host's TLS files are: the fleet authority's certificate (trust anchor), the host's
/// certificate and its private key.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HostTlsFiles {
    /// The fleet authority's certificate, `ca.pem`.
    pub ca: PathBuf,
    /// The host's certificate, `{host}.pem`.
    pub cert: PathBuf,
    /// The host's private key, `{host}.key`. Secret.
    pub key: PathBuf,
}

impl HostTlsFiles {
    /// The files of `host` in a fleet directory written by [`write_fleet_certs`].
    pub fn in_dir(dir: &Path, host: &HostName) -> Self {
        Self {
            ca: dir.join(CA_CERT_FILE),
            cert: dir.join(format!("{host}.pem")),
            key: dir.join(format!("{host}.key")),
        }
    }

    /// Checks that the three files are readable and hold what they should (a PEM certificate,
    /// a PEM private key), and that the key is not readable by other users. Zenoh reads them
    /// only when a session opens and says less about what is wrong.
    pub fn check(&self) -> Result<(), TlsFilesError> {
        check_pem(&self.ca, "certificate", |label| label == "CERTIFICATE")?;
        check_pem(&self.cert, "certificate", |label| label == "CERTIFICATE")?;
        check_pem(&self.key, "private key", |label| {
            label.ends_with("PRIVATE KEY")
        })?;
        let mode = fs::metadata(&self.key)
            .map_err(|source| TlsFilesError::Read {
                path: self.key.clone(),
                source,
            })?
            .permissions()
            .mode()
            & 0o777;
        if mode & 0o077 != 0 {
            return Err(TlsFilesError::KeyPermissions {
                path: self.key.clone(),
                mode,
            });
        }
        Ok(())
    }
}

fn check_pem(
    path: &Path,
    expected: &'static str,
    label_ok: fn(&str) -> bool,
) -> Result<(), TlsFilesError> {
    let text = fs::read(path).map_err(|source| TlsFilesError::Read {
        path: path.to_owned(),
        source,
    })?;
    match x509_parser::pem::parse_x509_pem(&text) {
        Ok((_, pem)) if label_ok(&pem.label) => Ok(()),
        _ => Err(TlsFilesError::NotPem {
            path: path.to_owned(),
            expected,
        }),
    }
}

/// What [`write_fleet_certs`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FleetCertFiles {
    /// The authority's certificate (public; every host needs it).
    pub ca_cert: PathBuf,
    /// The authority's key (secret; keep it where certificates are made).
    pub ca_key: PathBuf,
    /// Each host's files, in the order the hosts were given.
    pub hosts: Vec<(HostName, HostTlsFiles)>,
}

/// Makes a new fleet authority and a certificate for every host, and writes them into `dir`
/// (created with mode 0700 if missing): `ca.pem`, `ca.key`, `{host}.pem`, `{host}.key`; keys
/// get mode 0600.
///
/// Every host certificate carries [`DEFAULT_SANS`](super::DEFAULT_SANS), the host name when it
/// is a DNS label, and all of `extra_sans` (the addresses hosts dial each other by; shared, as
/// a host's identity is its Common Name, not its address).
///
/// Without `overwrite`, nothing is written if any of the files exists (a new authority would
/// orphan the certificates already handed out). Names and SANs are all checked before any file
/// is written.
pub fn write_fleet_certs(
    dir: &Path,
    hosts: &[String],
    extra_sans: &[String],
    overwrite: bool,
) -> Result<FleetCertFiles, CertWriteError> {
    let names = host_names(hosts)?;
    let authority = FleetAuthority::generate(FLEET_NAME)?;
    let identities = names
        .iter()
        .map(|host| authority.issue_host(host, extra_sans))
        .collect::<Result<Vec<_>, _>>()?;

    let ca_cert = dir.join(CA_CERT_FILE);
    let ca_key = dir.join(CA_KEY_FILE);
    let files: Vec<_> = names.iter().map(|h| HostTlsFiles::in_dir(dir, h)).collect();
    if !overwrite {
        let mut all = vec![&ca_cert, &ca_key];
        all.extend(files.iter().flat_map(|f| [&f.cert, &f.key]));
        refuse_existing(&all)?;
    }

    create_dir(dir)?;
    write_file(&ca_cert, authority.cert_pem(), PUBLIC_MODE, overwrite)?;
    write_file(&ca_key, &authority.key_pem(), SECRET_MODE, overwrite)?;
    for (identity, f) in identities.iter().zip(&files) {
        write_identity(identity, f, overwrite)?;
    }
    Ok(FleetCertFiles {
        ca_cert,
        ca_key,
        hosts: names.into_iter().zip(files).collect(),
    })
}

/// Issues a certificate for one more host with the authority already in `dir` (`ca.pem` and
/// `ca.key`) and writes `{host}.pem` and `{host}.key` (mode 0600). Refuses to replace the
/// host's files unless `overwrite`.
pub fn add_host_cert(
    dir: &Path,
    host: &str,
    extra_sans: &[String],
    overwrite: bool,
) -> Result<HostTlsFiles, CertWriteError> {
    let name = HostName::new(host).map_err(|source| CertWriteError::HostName {
        name: host.to_owned(),
        source,
    })?;
    let read = |path: PathBuf| {
        fs::read_to_string(&path).map_err(|source| CertWriteError::Io { path, source })
    };
    let authority = FleetAuthority::from_pem(
        &read(dir.join(CA_CERT_FILE))?,
        &read(dir.join(CA_KEY_FILE))?,
    )?;
    let identity = authority.issue_host(&name, extra_sans)?;
    let files = HostTlsFiles::in_dir(dir, &name);
    if !overwrite {
        refuse_existing(&[&files.cert, &files.key])?;
    }
    write_identity(&identity, &files, overwrite)?;
    Ok(files)
}

fn host_names(hosts: &[String]) -> Result<Vec<HostName>, CertWriteError> {
    if hosts.is_empty() {
        return Err(CertWriteError::NoHosts);
    }
    let mut names: Vec<HostName> = Vec::with_capacity(hosts.len());
    for host in hosts {
        let name = HostName::new(host).map_err(|source| CertWriteError::HostName {
            name: host.clone(),
            source,
        })?;
        if names
            .iter()
            .any(|n| n.as_str().eq_ignore_ascii_case(name.as_str()))
        {
            return Err(CertWriteError::DuplicateHost(host.clone()));
        }
        names.push(name);
    }
    Ok(names)
}

fn refuse_existing(paths: &[&PathBuf]) -> Result<(), CertWriteError> {
    for path in paths {
        // `symlink_metadata`: a dangling link would still be written through.
        if fs::symlink_metadata(path).is_ok() {
            return Err(CertWriteError::Exists((*path).clone()));
        }
    }
    Ok(())
}

fn create_dir(dir: &Path) -> Result<(), CertWriteError> {
    DirBuilder::new()
        .recursive(true)
        .mode(DIR_MODE)
        .create(dir)
        .map_err(|source| CertWriteError::Io {
            path: dir.to_owned(),
            source,
        })
}

fn write_identity(
    identity: &HostIdentity,
    files: &HostTlsFiles,
    overwrite: bool,
) -> Result<(), CertWriteError> {
    write_file(&files.cert, &identity.cert_pem, PUBLIC_MODE, overwrite)?;
    write_file(&files.key, &identity.key_pem, SECRET_MODE, overwrite)
}

/// Writes a file with exactly `mode`. A new file is created with it (never readable by others,
/// even for an instant); a replaced one gets it before the contents are written.
fn write_file(
    path: &Path,
    contents: &str,
    mode: u32,
    overwrite: bool,
) -> Result<(), CertWriteError> {
    let io_error = |source: io::Error| {
        if source.kind() == io::ErrorKind::AlreadyExists {
            CertWriteError::Exists(path.to_owned())
        } else {
            CertWriteError::Io {
                path: path.to_owned(),
                source,
            }
        }
    };
    let mut options = OpenOptions::new();
    options.write(true).mode(mode);
    if overwrite {
        options.create(true).truncate(true);
    } else {
        options.create_new(true);
    }
    let mut file = options.open(path).map_err(io_error)?;
    file.set_permissions(Permissions::from_mode(mode))
        .map_err(io_error)?;
    file.write_all(contents.as_bytes()).map_err(io_error)?;
    file.sync_all().map_err(io_error)
}
