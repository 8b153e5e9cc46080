//! Session configurations: explicit endpoints, scouting on or off.

use crate::Error;

/// A peer-mode Zenoh configuration that listens on `listen` and connects to `connect`
/// (endpoints such as `tcp/127.0.0.1:7447`), with multicast scouting on or off.
/// Multicast scouting finds peers on a LAN without naming them; tests and machines
/// without multicast name their endpoints and turn it off.
pub fn peer_config(
    listen: &[String],
    connect: &[String],
    multicast: bool,
) -> Result<zenoh::Config, Error> {
    let mut config = zenoh::Config::default();
    let list = |endpoints: &[String]| {
        serde_json::to_string(endpoints).expect("a list of strings serializes")
    };
    config
        .insert_json5("mode", "\"peer\"")
        .map_err(Error::zenoh)?;
    config
        .insert_json5("listen/endpoints", &list(listen))
        .map_err(Error::zenoh)?;
    config
        .insert_json5("connect/endpoints", &list(connect))
        .map_err(Error::zenoh)?;
    config
        .insert_json5(
            "scouting/multicast/enabled",
            if multicast { "true" } else { "false" },
        )
        .map_err(Error::zenoh)?;
    Ok(config)
}
