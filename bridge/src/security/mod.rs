//! The bridge's security: the fleet's certificates, mutually authenticated TLS links (QUIC by
//! default, or TLS over TCP: [`SECURE_PROTOCOLS`]) and
//! Zenoh's access control, so that only the fleet's hosts join a run and each publishes only
//! what its role allows.
//!
//! # The threat
//!
//! Each UAV fuses its peers' estimates by *intersecting* their sets of cells that may hold a
//! target: a peer's estimate removes every cell it says is free. So one forged estimate
//! claiming that the whole region is free empties every UAV's set, and the fleet loses every
//! target at once. A forged frame, command or guidance token does similar damage. Over
//! iceoryx2, only processes of the same machine and user can publish; once the bridge carries
//! a run over the network, anyone who reaches a bridge's port could, unless:
//!
//! - **TLS with mutual authentication** lets only hosts holding a certificate signed by the
//!   fleet authority open a link (in both directions: the listener checks the connecting
//!   host's certificate, the connecting host checks the listener's), and encrypts the links.
//!   A stranger, with no certificate or one of another authority, cannot connect, so nothing it
//!   sends arrives anywhere.
//! - **The access control** (Zenoh's ACL) limits what a fleet host may do to its role. A host
//!   is known by its certificate's Common Name, its host name, which only the fleet authority
//!   can vouch for. The host at the receiving end of a link (the router, in the bridge's
//!   layout) drops any publication its sender may not make, so a compromised agent host can
//!   forge no other host's estimates, nor frames.
//!   (Zenoh checks again on the sending side, but a malicious host controls its own sending
//!   side: the receiver's check is the one that protects.)
//!
//! Neither protects against a compromised host lying *within* its role (its own UAVs'
//! estimates), nor against the holder of `ca.key`, who can make a certificate with any name.
//!
//! # What is secret
//!
//! The `*.key` files: `ca.key` lets one issue certificates (keep it only where certificates are
//! made), `{host}.key` lets one be that host (copy it to that host only). Both are written with
//! mode 0600, and [`HostTlsFiles::check`] refuses a host key other users can read. The `.pem`
//! files are certificates: public, every host needs `ca.pem` and its own `{host}.pem`.
//!
//! # Making certificates
//!
//! `fleet certs --out DIR --hosts world,h1,h2` calls [`write_fleet_certs`]: a new authority and
//! one certificate per host (valid for `localhost`, `127.0.0.1`, the host name when it is a DNS
//! label, and any extra names given: the addresses hosts dial each other by). It refuses to
//! overwrite existing files unless asked. [`add_host_cert`] issues one more host later with the
//! authority in `DIR`. Then copy `ca.pem`, `{host}.pem` and `{host}.key` to each host, and open
//! its session with [`zenoh_config`] and [`HostTlsFiles::in_dir`].
//!
//! # Key expressions and roles
//!
//! The keys are spelled by [`crate::keys`]; the policy builds its rules from the same
//! functions.
//!
//! | key expression                    | published by                 | built by |
//! |-----------------------------------|------------------------------|----------|
//! | `setfleet/{run}/uav/{i}/cvs`      | world host                   | [`keys::frame`](crate::keys::frame) |
//! | `setfleet/{run}/world/**`         | world host                   | [`keys::end_of_run`](crate::keys::end_of_run) |
//! | `setfleet/{run}/uav/{i}/cmd`      | host running UAV `i`         | [`keys::command`](crate::keys::command) |
//! | `setfleet/{run}/uav/{i}/estimate` | host running UAV `i`         | [`keys::estimate`](crate::keys::estimate) |
//! | `setfleet/{run}/uav/{i}/state`    | host running UAV `i`         | [`keys::state`](crate::keys::state) |
//! | `setfleet/{run}/guidance/{i}`     | host running UAV `i`         | [`keys::token`](crate::keys::token) |
//! | `setfleet/{run}/alive/{host}/{node}` | liveliness of `host`'s own processes | [`keys::alive`](crate::keys::alive) |
//! | `setfleet/{run}/**`, `.../alive/**` | the relay (router), relaying | |
//!
//! Every host named in the [`AccessPolicy`] may subscribe to `setfleet/{run}/**` and watch
//! liveliness under `setfleet/{run}/alive/**`; everything else is denied.
//!
//! # Topology
//!
//! Links are only the endpoints of the [`LinkPlan`]: no multicast scouting, no gossip. The ACL
//! judges a message by the host at the other end of the link it arrived on:
//!
//! - **Router and clients** (the bridge's layout): the world host is a Zenoh router, the
//!   others are clients connecting to it, and the router relays between them. The router
//!   enforces the roles (a client's message outside its role stops there); the clients accept
//!   anything of the run from the router, marked [`AccessPolicy::relay_host`], and nothing
//!   from anyone else (should a fleet host manage to pose as the router's address, its
//!   messages would be judged by its own role). The router is trusted with the whole run.
//! - **Peers**: Zenoh peers do not relay one peer's messages to another, so every pair of
//!   peers exchanging data needs a direct link, and each message is judged by its author's
//!   role at every receiver. No relay host then.
//!
//! # Zenoh behaviours worth knowing (1.10)
//!
//! - A refused TLS handshake is logged by the *listening* side only, as a `WARN` of target
//!   `zenoh_link_tls::unicast` holding the rustls error followed by a misleading hint, e.g.
//!   `peer sent no certificates. Hint: increase the system open file limit.` or
//!   `invalid peer certificate: UnknownIssuer. Hint: ...`. Keep `zenoh_link_tls=warn` in the
//!   log filter to see intruders. A connecting peer retries in the background without error.
//! - An ACL refusal is logged only at `TRACE` (`... is unauthorized to Put (ingress) on ...`);
//!   a link whose certificate matches no subject is logged at `INFO` (`did not match any
//!   configured ACL subject`).
//! - A connecting host trusts the fleet authority *and* the public web authorities (Zenoh adds
//!   them): a server with a public certificate for the dialled name passes TLS. The ACL still
//!   denies it everything, as a public certificate's Common Name is a domain name and host
//!   names have no dot.
//!
//! # Example
//!
//! **World host (the router)**
//!
//! ```no_run
//! use std::path::Path;
//! use bridge::keys;
//! use bridge::security::{self, AccessPolicy, HostName, HostTlsFiles, LinkMode, LinkPlan};
//! use protocol::service::RunId;
//! use zenoh::Wait;
//! # fn main() -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
//! let run = RunId::new("demo")?;
//! let world = HostName::new("world")?;
//! let policy = AccessPolicy::new(&run)
//!     .world_host(&world)?
//!     .relay_host(&world)
//!     .agent_host(&HostName::new("h1")?, &[0, 1])?;
//! let tls = HostTlsFiles::in_dir(Path::new("certs"), &world);
//! let link = LinkPlan {
//!     mode: LinkMode::Router,
//!     listen: vec!["quic/0.0.0.0:7447".into()],
//!     connect: vec![],
//! };
//! let session = zenoh::open(security::zenoh_config(&link, Some(&tls), Some(&policy))?).wait()?;
//! let estimates = session.declare_subscriber(keys::estimate(&run, 0)).wait()?;
//! # drop(estimates);
//! # Ok(())
//! # }
//! ```
//!
//! **Agent host `h1` (a client)**: the same policy, its own files, and
//! `LinkPlan { mode: LinkMode::Client, listen: vec![], connect: vec!["quic/10.0.0.1:7447".into()] }`
//! (the address must be one of the router's certificate names).

mod access;
mod authority;
mod cert_files;
mod host;
mod link;

pub use access::{AccessPolicy, AccessPolicyError};
pub use authority::{
    AuthorityError, CA_VALIDITY_DAYS, DEFAULT_SANS, FleetAuthority, HOST_VALIDITY_DAYS,
    HostIdentity,
};
pub use cert_files::{
    CA_CERT_FILE, CA_KEY_FILE, CertWriteError, FLEET_NAME, FleetCertFiles, HostTlsFiles,
    TlsFilesError, add_host_cert, write_fleet_certs,
};
pub use host::{HostName, HostNameError};
pub use link::{ConfigBuildError, LinkMode, LinkPlan, SECURE_PROTOCOLS, zenoh_config};
