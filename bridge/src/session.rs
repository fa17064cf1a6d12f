//! Zenoh session configuration (temporary: plain TCP).

use serde_json::json;

/// A Zenoh configuration: router listening on `listen` for the world host, client connecting
/// to `connect` otherwise; no scouting.
pub fn plain_config(
    router: bool,
    listen: &[String],
    connect: &[String],
) -> Result<zenoh::Config, zenoh::Error> {
    let mut c = zenoh::Config::default();
    let mode = if router { "router" } else { "client" };
    c.insert_json5("mode", &json!(mode).to_string())?;
    c.insert_json5("listen/endpoints", &json!(listen).to_string())?;
    c.insert_json5("connect/endpoints", &json!(connect).to_string())?;
    c.insert_json5("scouting/multicast/enabled", "false")?;
    c.insert_json5("scouting/gossip/enabled", "false")?;
    if !router {
        c.insert_json5("connect/timeout_ms", "30000")?;
        c.insert_json5(
            "connect/retry",
            r#"{ period_init_ms: 50, period_max_ms: 1000, period_increase_factor: 2 }"#,
        )?;
    }
    Ok(c)
}
