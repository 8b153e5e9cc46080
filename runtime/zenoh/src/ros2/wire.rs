//! What a ROS 2 topic is on rmw_zenoh's wire (`docs/ros2.md`, "Topics on the
//! rmw_zenoh wire"): the data key expression, the liveliness tokens of a node and of
//! its publishers and subscriptions with their QoS, the attachment of each message,
//! an entity's GID, and the ROS 2 name rules. Pure functions: no session here.

use std::fmt;

use crate::limits;

/// The administration space of rmw_zenoh's liveliness tokens.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// The length of an rmw_zenoh attachment: the sequence number and the source
/// timestamp (each an `i64`, little endian), the GID's length (one byte, 16) and the
/// GID's 16 bytes.
pub const ATTACHMENT_LEN: usize = 8 + 8 + 1 + GID_LEN;

/// The length of a GID (`RMW_GID_STORAGE_SIZE`).
pub const GID_LEN: usize = 16;

/// The longest ROS 2 node name, namespace or topic name accepted, in bytes.
pub const MAX_NAME: usize = limits::ROS_NAME.max;

/// What an entity's liveliness token says it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    /// A node (`NN`).
    Node,
    /// A publisher (`MP`).
    Publisher,
    /// A subscription (`MS`).
    Subscription,
}

impl EntityKind {
    /// Its code in a token.
    pub fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
        }
    }
}

/// Reliability (`rmw_qos_reliability_policy_e`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Reliability {
    /// Every message is delivered, retransmitted if need be (`1`). The default.
    #[default]
    Reliable,
    /// A message may be lost (`2`).
    BestEffort,
}

/// History (`rmw_qos_history_policy_e`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum History {
    /// Keep the last `n` messages (`1`).
    KeepLast(u32),
    /// Keep them all (`2`).
    KeepAll,
}

impl Default for History {
    /// Keep the last 10, as ROS 2's default topic QoS.
    fn default() -> History {
        History::KeepLast(10)
    }
}

/// The QoS of a publisher or subscription as its liveliness token tells it. The
/// durability is volatile (no message is kept for a late joiner), the deadline,
/// lifespan and liveliness lease infinite and the liveliness automatic: those are
/// not settable here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Qos {
    /// Reliability.
    pub reliability: Reliability,
    /// History.
    pub history: History,
}

/// rmw_zenoh's default depth, written in a token only when another is used.
const RMW_ZENOH_DEFAULT_DEPTH: u32 = 42;

impl Qos {
    /// The token's QoS field, as rmw_zenoh's `qos_to_keyexpr` writes it: a field
    /// equal to rmw_zenoh's default (reliable, volatile, keep last 42, infinite
    /// durations, automatic liveliness) is empty. ROS 2's default (keep last 10) is
    /// `::,10:,:,:,,`.
    pub fn token_field(&self) -> String {
        let reliability = match self.reliability {
            Reliability::Reliable => "",
            Reliability::BestEffort => "2",
        };
        let (kind, depth) = match self.history {
            History::KeepLast(depth) => ("", depth),
            // rmw_zenoh keeps the depth it was given; a keep-all QoS from rclcpp has
            // depth 0, which its best-available rule turns into its default.
            History::KeepAll => ("2", RMW_ZENOH_DEFAULT_DEPTH),
        };
        let depth = if depth == RMW_ZENOH_DEFAULT_DEPTH {
            String::new()
        } else {
            depth.to_string()
        };
        // Reliability, durability (volatile: the default), history kind and depth,
        // deadline, lifespan, liveliness and its lease.
        format!("{reliability}::{kind},{depth}:,:,:,,")
    }
}

/// rmw_zenoh's mangling of a name inside a token: each `/` becomes `%`.
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// A node as its tokens name it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeInfo {
    /// The ROS domain id.
    pub domain: u32,
    /// The Zenoh session's id, as Zenoh prints it.
    pub zid: String,
    /// The node's id within its session.
    pub nid: u64,
    /// The node's enclave (`/` when none).
    pub enclave: String,
    /// Its namespace (`/`, `/robot`).
    pub namespace: String,
    /// Its name.
    pub name: String,
}

impl NodeInfo {
    /// The node's liveliness token:
    /// `@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<name>`, names
    /// mangled.
    pub fn token(&self) -> String {
        self.prefix(self.nid, EntityKind::Node)
    }

    fn prefix(&self, id: u64, kind: EntityKind) -> String {
        format!(
            "{ADMIN_SPACE}/{}/{}/{}/{id}/{}/{}/{}/{}",
            self.domain,
            self.zid,
            self.nid,
            kind.code(),
            mangle(&self.enclave),
            mangle(&self.namespace),
            mangle(&self.name)
        )
    }

    /// A publisher's or subscription's liveliness token: the node's fields with the
    /// entity's id and kind, then the topic, the DDS type name, the type hash (all
    /// mangled) and the QoS.
    pub fn endpoint_token(&self, id: u64, kind: EntityKind, topic: &TopicInfo) -> String {
        format!(
            "{}/{}/{}/{}/{}",
            self.prefix(id, kind),
            mangle(&topic.name),
            mangle(&topic.dds_type),
            mangle(&topic.type_hash),
            topic.qos.token_field()
        )
    }
}

/// A topic as rmw_zenoh keys it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// The ROS domain id.
    pub domain: u32,
    /// The fully qualified topic name (`/scan`).
    pub name: String,
    /// The message type's DDS name (`sensor_msgs::msg::dds_::LaserScan_`).
    pub dds_type: String,
    /// Its RIHS01 type hash.
    pub type_hash: String,
    /// The endpoint's QoS.
    pub qos: Qos,
}

impl TopicInfo {
    /// The data key expression:
    /// `<domain>/<topic without its leading slash>/<dds type>/<type hash>`.
    pub fn key(&self) -> String {
        format!(
            "{}/{}/{}/{}",
            self.domain,
            self.name.trim_start_matches('/'),
            self.dds_type,
            self.type_hash
        )
    }
}

/// An entity's GID, as rmw_zenoh makes it: the XXH3-128 of its liveliness token's
/// key expression, its low 64 bits then its high 64 bits, each little endian (the
/// 128-bit value in little-endian byte order).
pub fn gid(token: &str) -> [u8; GID_LEN] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

/// What each message carries beside its payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// The publisher's sequence number (1 for its first message).
    pub sequence: i64,
    /// When it was published, in nanoseconds since the Unix epoch.
    pub timestamp: i64,
    /// The publisher's GID.
    pub gid: [u8; GID_LEN],
}

/// An attachment that is not rmw_zenoh's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "an attachment of {len} bytes with GID length {gid_len}, expected {ATTACHMENT_LEN} bytes with GID length {GID_LEN}"
)]
pub struct BadAttachment {
    /// Its length.
    pub len: usize,
    /// The GID length it says (0 when too short to say).
    pub gid_len: u8,
}

impl Attachment {
    /// The bytes rmw_zenoh's `AttachmentData::serialize_to_zbytes` writes (Zenoh's
    /// serializer: two `i64`, then the 16-byte array as a sequence, its length a
    /// one-byte LEB128).
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut bytes = [0u8; ATTACHMENT_LEN];
        bytes[..8].copy_from_slice(&self.sequence.to_le_bytes());
        bytes[8..16].copy_from_slice(&self.timestamp.to_le_bytes());
        bytes[16] = GID_LEN as u8;
        bytes[17..].copy_from_slice(&self.gid);
        bytes
    }

    /// Decode exactly those bytes.
    pub fn decode(bytes: &[u8]) -> Result<Attachment, BadAttachment> {
        let gid_len = bytes.get(16).copied().unwrap_or(0);
        if bytes.len() != ATTACHMENT_LEN || usize::from(gid_len) != GID_LEN {
            return Err(BadAttachment {
                len: bytes.len(),
                gid_len,
            });
        }
        let word = |range: std::ops::Range<usize>| {
            let mut word = [0u8; 8];
            word.copy_from_slice(&bytes[range]);
            i64::from_le_bytes(word)
        };
        let mut gid = [0u8; GID_LEN];
        gid.copy_from_slice(&bytes[17..]);
        Ok(Attachment {
            sequence: word(0..8),
            timestamp: word(8..16),
            gid,
        })
    }
}

/// A ROS 2 name that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "invalid ROS 2 {what} `{}`: {reason}",
    coolbot::ranges::excerpt(.name, coolbot::ranges::EXCERPT_CHARS)
)]
pub struct BadName {
    /// What it names (`node name`, `namespace`, `topic name`).
    pub what: &'static str,
    /// The name.
    pub name: String,
    /// Why.
    pub reason: String,
}

impl fmt::Display for EntityKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.code())
    }
}

fn bad(what: &'static str, name: &str, reason: impl Into<String>) -> BadName {
    BadName {
        what,
        name: name.to_owned(),
        reason: reason.into(),
    }
}

/// One token of a name (between slashes): letters, digits and `_`, not starting
/// with a digit.
fn check_token(what: &'static str, name: &str, token: &str) -> Result<(), BadName> {
    if token.is_empty() {
        return Err(bad(what, name, "an empty token (`//`, or `/` at the end)"));
    }
    if let Some(c) = token
        .chars()
        .find(|c| !c.is_ascii_alphanumeric() && *c != '_')
    {
        let allowed = if what == "node name" {
            "only letters, digits and `_` are allowed (a node name is one token: the \
             rest of a path goes in the namespace)"
        } else {
            "only letters, digits, `_` and `/` are allowed"
        };
        return Err(bad(what, name, format!("`{c}`: {allowed}")));
    }
    if token.starts_with(|c: char| c.is_ascii_digit()) {
        return Err(bad(
            what,
            name,
            format!("the token `{token}` starts with a digit"),
        ));
    }
    Ok(())
}

fn check_length(what: &'static str, name: &str) -> Result<(), BadName> {
    limits::ROS_NAME
        .check(|| format!("the {what}"), name.len())
        .map_err(|exceeded| bad(what, name, exceeded.to_string()))
}

/// A node name: one token.
pub fn check_node_name(name: &str) -> Result<(), BadName> {
    check_length("node name", name)?;
    check_token("node name", name, name)
}

/// A namespace: `/`, or absolute tokens (`/robot/left`).
pub fn check_namespace(namespace: &str) -> Result<(), BadName> {
    check_length("namespace", namespace)?;
    if namespace == "/" {
        return Ok(());
    }
    let Some(rest) = namespace.strip_prefix('/') else {
        return Err(bad("namespace", namespace, "it does not start with `/`"));
    };
    rest.split('/')
        .try_for_each(|token| check_token("namespace", namespace, token))
}

/// The fully qualified name of `topic` in `namespace`: an absolute topic as it is
/// (`/scan`), a relative one under the namespace (`scan` in `/robot` is
/// `/robot/scan`). A private name (`~/x`) and substitutions (`{node}`) are refused.
pub fn qualify(namespace: &str, topic: &str) -> Result<String, BadName> {
    if topic.starts_with('~') {
        return Err(bad(
            "topic name",
            topic,
            "a private name (`~/...`) is not supported: give it relative to the \
             namespace, or absolute",
        ));
    }
    if topic.contains(['{', '}']) {
        return Err(bad(
            "topic name",
            topic,
            "substitutions (`{node}`, `{ns}`) are not supported",
        ));
    }
    let full = if topic.starts_with('/') {
        topic.to_owned()
    } else if namespace == "/" {
        format!("/{topic}")
    } else {
        format!("{namespace}/{topic}")
    };
    check_length("topic name", &full)?;
    full[1..]
        .split('/')
        .try_for_each(|token| check_token("topic name", topic, token))?;
    Ok(full)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node() -> NodeInfo {
        NodeInfo {
            domain: 7,
            zid: "a1b2c3".into(),
            nid: 0,
            enclave: "/".into(),
            namespace: "/".into(),
            name: "base".into(),
        }
    }

    fn scan() -> TopicInfo {
        TopicInfo {
            domain: 7,
            name: "/robot/scan".into(),
            dds_type: "sensor_msgs::msg::dds_::LaserScan_".into(),
            type_hash: "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"
                .into(),
            qos: Qos::default(),
        }
    }

    /// rmw_zenoh's parse of a token (`liveliness::Entity::make(keyexpr)` and
    /// `keyexpr_to_qos`), for the fields it checks: the parts, none empty, the
    /// admin space, the kind, and for an endpoint 13 parts with a QoS of six fields.
    fn rmw_zenoh_parses(token: &str) -> Result<Vec<String>, String> {
        let parts: Vec<String> = token.split('/').map(str::to_owned).collect();
        if parts.len() < 9 || parts.iter().any(String::is_empty) || parts[0] != ADMIN_SPACE {
            return Err(format!("not a token: {token}"));
        }
        parts[1].parse::<u64>().map_err(|e| e.to_string())?;
        match parts[5].as_str() {
            "NN" => {}
            "MP" | "MS" => {
                if parts.len() < 13 {
                    return Err(format!("an endpoint without its topic: {token}"));
                }
                let qos: Vec<&str> = parts[12].split(':').collect();
                let fields = [2usize, 2, 2, 3];
                if qos.len() < 6
                    || qos[2..6]
                        .iter()
                        .zip(fields)
                        .any(|(field, n)| field.split(',').count() < n)
                {
                    return Err(format!("a QoS rmw_zenoh does not read: {}", parts[12]));
                }
            }
            other => return Err(format!("unknown kind {other}")),
        }
        Ok(parts
            .into_iter()
            .map(|part| part.replace('%', "/"))
            .collect())
    }

    #[test]
    fn the_data_key_is_domain_topic_type_and_hash() {
        assert_eq!(
            scan().key(),
            "7/robot/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"
        );
    }

    #[test]
    fn a_node_token_is_what_rmw_zenoh_writes_and_parses() {
        let token = node().token();
        assert_eq!(token, "@ros2_lv/7/a1b2c3/0/0/NN/%/%/base");
        let parts = rmw_zenoh_parses(&token).unwrap();
        assert_eq!(parts[6..], ["/", "/", "base"]);
    }

    #[test]
    fn an_endpoint_token_carries_the_topic_type_hash_and_qos() {
        let token = node().endpoint_token(3, EntityKind::Publisher, &scan());
        assert_eq!(
            token,
            "@ros2_lv/7/a1b2c3/0/3/MP/%/%/base/%robot%scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828/::,10:,:,:,,"
        );
        let parts = rmw_zenoh_parses(&token).unwrap();
        assert_eq!(parts[9], "/robot/scan");
        let mut sub = node();
        sub.namespace = "/robot/left".into();
        let token = sub.endpoint_token(4, EntityKind::Subscription, &scan());
        assert!(token.contains("/4/MS/%/%robot%left/base/"), "{token}");
        assert_eq!(rmw_zenoh_parses(&token).unwrap()[7], "/robot/left");
    }

    #[test]
    fn qos_fields_equal_to_rmw_zenohs_defaults_are_empty() {
        let qos = |reliability, history| {
            Qos {
                reliability,
                history,
            }
            .token_field()
        };
        assert_eq!(
            qos(Reliability::Reliable, History::KeepLast(10)),
            "::,10:,:,:,,"
        );
        assert_eq!(
            qos(Reliability::Reliable, History::KeepLast(42)),
            "::,:,:,:,,"
        );
        assert_eq!(
            qos(Reliability::BestEffort, History::KeepLast(5)),
            "2::,5:,:,:,,"
        );
        assert_eq!(qos(Reliability::Reliable, History::KeepAll), "::2,:,:,:,,");
    }

    #[test]
    fn the_attachment_is_two_words_and_a_sized_gid() {
        let attachment = Attachment {
            sequence: 1,
            timestamp: 0x0102_0304_0506_0708,
            gid: [0xaa; GID_LEN],
        };
        let bytes = attachment.encode();
        assert_eq!(bytes[..8], [1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(bytes[8..16], [8, 7, 6, 5, 4, 3, 2, 1]);
        assert_eq!(bytes[16], 16);
        assert_eq!(Attachment::decode(&bytes), Ok(attachment));
        assert_eq!(
            Attachment::decode(&bytes[..20]),
            Err(BadAttachment {
                len: 20,
                gid_len: 16
            })
        );
        let mut wrong = bytes;
        wrong[16] = 15;
        assert!(Attachment::decode(&wrong).is_err());
        assert!(Attachment::decode(&[]).is_err());
    }

    #[test]
    fn the_gid_is_the_xxh3_128_of_the_token() {
        // Expected values: Python's `xxhash` 3.x,
        // `xxhash.xxh3_128_intdigest(token).to_bytes(16, "little")`; the last token
        // is past 128 bytes, XXH3's long-input path.
        let hex =
            |bytes: [u8; GID_LEN]| -> String { bytes.iter().map(|b| format!("{b:02x}")).collect() };
        assert_eq!(hex(gid("")), "7f498d4624c30160d8984701d306aa99");
        assert_eq!(
            hex(gid("@ros2_lv/0/a/0/0/NN/%/%/x")),
            "0dd45bdf862279489bb0d3e09d07474d"
        );
        let publisher = "@ros2_lv/0/0123456789abcdef0123456789abcdef/0/1/MP/%/%/talker/\
            %chatter/std_msgs::msg::dds_::String_/\
            RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,";
        assert!(publisher.len() > 128);
        assert_eq!(hex(gid(publisher)), "0cf037d088b0aae8f10816401289d361");
    }

    #[test]
    fn names_follow_ros_2s_rules() {
        assert_eq!(qualify("/", "/scan").unwrap(), "/scan");
        assert_eq!(qualify("/", "scan").unwrap(), "/scan");
        assert_eq!(qualify("/robot", "scan").unwrap(), "/robot/scan");
        assert_eq!(qualify("/robot", "/cmd_vel").unwrap(), "/cmd_vel");
        for wrong in [
            "/scan/",
            "//scan",
            "/2d",
            "~/scan",
            "/sc an",
            "/{node}/x",
            "",
        ] {
            let error = qualify("/", wrong).unwrap_err();
            assert_eq!(error.what, "topic name", "{wrong}");
        }
        check_node_name("base_1").unwrap();
        assert!(check_node_name("1base").is_err());
        let slash = check_node_name("a/b").unwrap_err();
        assert!(slash.reason.contains("a node name is one token"), "{slash}");
        let private = qualify("/", "~/scan").unwrap_err();
        assert!(private.reason.starts_with("a private name"), "{private}");
        let substituted = qualify("/", "/{node}/x").unwrap_err();
        assert!(
            substituted.reason.starts_with("substitutions"),
            "{substituted}"
        );
        check_namespace("/").unwrap();
        check_namespace("/robot/left").unwrap();
        for wrong in ["robot", "/robot/", "//"] {
            assert!(check_namespace(wrong).is_err(), "{wrong}");
        }
        let long = format!("/{}", "a".repeat(MAX_NAME));
        let error = qualify("/", &long).unwrap_err();
        assert!(
            error.reason.contains("over the limit ROS_NAME = 255 bytes"),
            "{error}"
        );
    }
}
