//! The packet of the recording tests (`record.rs`), the extern packet `RecordSample`
//! of `cool/record.cool`: a sample whose serialization a test can hold (a slow disk)
//! or make fail.

use std::sync::Arc;
use std::time::Duration;

use coolbot::crossbeam_channel::{Receiver, Sender};
use serde::ser::{Error as _, SerializeStruct};
use serde::{Deserialize, Serialize, Serializer};

/// How long a held serialization waits at most for its release.
const HOLD: Duration = Duration::from_secs(20);

/// What the recorder's thread does when it serializes a sample that carries one.
#[derive(Debug)]
pub struct Hook {
    /// Fail to serialize.
    pub fail: bool,
    /// Told when serialization starts.
    pub entered: Sender<()>,
    /// Serialization waits for this (or its sender's drop).
    pub release: Receiver<()>,
}

/// The packet type of the tests.
#[derive(Clone, Debug, Deserialize)]
pub struct Sample {
    pub n: u64,
    pub label: String,
    #[serde(skip)]
    pub hook: Option<Arc<Hook>>,
}

impl PartialEq for Sample {
    fn eq(&self, other: &Sample) -> bool {
        self.n == other.n && self.label == other.label
    }
}

impl Serialize for Sample {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        if let Some(hook) = &self.hook {
            if hook.fail {
                return Err(S::Error::custom("a sample that refuses to serialize"));
            }
            let _ = hook.entered.send(());
            let _ = hook.release.recv_timeout(HOLD);
        }
        let mut fields = serializer.serialize_struct("Sample", 2)?;
        fields.serialize_field("n", &self.n)?;
        fields.serialize_field("label", &self.label)?;
        fields.end()
    }
}

/// Sample `n`, labelled `sample n`.
pub fn sample(n: u64) -> Sample {
    Sample {
        n,
        label: format!("sample {n}"),
        hook: None,
    }
}

/// The sample as a ROS 2 message type, `coolbot_test/msg/Sample` (`uint64 n`,
/// `string label`: its fields in order), so that a rosbag2 recording takes it and
/// its serialization can still be held. The hash is rosbags' (`hash_rihs01`) for
/// that definition.
impl coolbot::ros::RosType for Sample {
    const NAME: &'static str = "coolbot_test/msg/Sample";
    const DDS_NAME: &'static str = "coolbot_test::msg::dds_::Sample_";
    const TYPE_HASH: &'static str =
        "RIHS01_05a37d5b6436413f50ea217f8295c383cd7ec93bf6934dfe8c58257a26303f09";
    const MESSAGE_DEFINITION: &'static str = "uint64 n\nstring label\n";
}
