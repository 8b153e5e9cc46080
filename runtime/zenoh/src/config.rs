//! Session configurations: explicit endpoints, scouting on or off, and the node's
//! security ([`Security`]).

use crate::Error;
use crate::security::Security;

/// A peer-mode Zenoh configuration that listens on `listen` and connects to `connect`
/// (endpoints such as `tcp/127.0.0.1:7447`), with multicast scouting on or off, and
/// no security file: [`secure_config`] with [`Security::none`], so every endpoint must
/// be on loopback and multicast scouting off (a clear error otherwise).
pub fn peer_config(
    listen: &[String],
    connect: &[String],
    multicast: bool,
) -> Result<zenoh::Config, Error> {
    secure_config(listen, connect, multicast, &Security::none())
}

/// [`peer_config`] under `security`: endpoints are checked against it (`quic/` and
/// `tls/` endpoints need its TLS; `tcp/` endpoints off loopback, and multicast scouting,
/// need TLS or plaintext allowed), then its TLS and access rules are written into the
/// configuration (`docs/distribution.md`, "Security"). Multicast scouting finds peers
/// on a LAN without naming them; tests and machines without multicast name their
/// endpoints and turn it off.
pub fn secure_config(
    listen: &[String],
    connect: &[String],
    multicast: bool,
    security: &Security,
) -> Result<zenoh::Config, Error> {
    security.check(listen, connect, multicast)?;
    let mut config = zenoh::Config::default();
    let list = |endpoints: &[String]| {
        serde_json::to_string(endpoints).expect("a list of strings serializes")
    };
    config
        .insert_json5("mode", "\"peer\"")
        .map_err(Error::zenoh("set the mode"))?;
    config
        .insert_json5("listen/endpoints", &list(listen))
        .map_err(Error::zenoh("set the listen endpoints"))?;
    config
        .insert_json5("connect/endpoints", &list(connect))
        .map_err(Error::zenoh("set the connect endpoints"))?;
    config
        .insert_json5(
            "scouting/multicast/enabled",
            if multicast { "true" } else { "false" },
        )
        .map_err(Error::zenoh("set multicast scouting"))?;
    security.apply(&mut config)?;
    Ok(config)
}
