//! A node with a security file (`docs/distribution.md`, "Security") against the
//! `coolctl` binary with `--config` as an operator runs it: TLS with mutual
//! authentication and access rules, and plaintext refused off loopback. Certificates
//! are made here with rcgen: a CA, the robot's and the operator's certificates signed
//! by it, and an intruder's from another CA. (The tests of the same rules without the
//! binary, on generated components: `tests/zenoh/tests/security.rs`; these need the
//! binary, which only this package's tests can run.)

mod support;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use coolbot::State;
use coolbot_zenoh::{Node, Security, secure_config};
use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair};

use support::{PATIENCE, free_port, robot, wait_until};

/// A certificate authority: its certificate in `dir/<name>-ca.pem`, and what signs.
struct Authority {
    ca: PathBuf,
    issuer: Issuer<'static, KeyPair>,
}

impl Authority {
    fn new(dir: &Path, name: &str) -> Authority {
        let key = KeyPair::generate().expect("a CA key");
        let mut params = CertificateParams::new(Vec::<String>::new()).expect("CA params");
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.distinguished_name.push(DnType::CommonName, name);
        let certificate = params.self_signed(&key).expect("a self-signed CA");
        let ca = dir.join(format!("{name}-ca.pem"));
        std::fs::write(&ca, certificate.pem()).expect("write the CA");
        Authority {
            ca,
            issuer: Issuer::new(params, key),
        }
    }

    /// A security file for the node whose certificate's common name is `name`, with
    /// `rules` (TOML `[[allow]]` tables) after its `[tls]` table.
    fn node(&self, dir: &Path, file: &str, name: &str, rules: &str) -> PathBuf {
        self.node_with(dir, file, name, "", rules)
    }

    /// [`Authority::node`] with `top` (top-level keys) before the `[tls]` table.
    fn node_with(&self, dir: &Path, file: &str, name: &str, top: &str, rules: &str) -> PathBuf {
        let key = KeyPair::generate().expect("a node key");
        let mut params =
            CertificateParams::new(vec!["localhost".to_owned(), "127.0.0.1".to_owned()])
                .expect("node params");
        params.distinguished_name.push(DnType::CommonName, name);
        let certificate = params.signed_by(&key, &self.issuer).expect("signed");
        std::fs::write(dir.join(format!("{file}.pem")), certificate.pem()).expect("write");
        std::fs::write(dir.join(format!("{file}.key")), key.serialize_pem()).expect("write");
        let path = dir.join(format!("{file}.toml"));
        let ca = self.ca.file_name().expect("a file").to_string_lossy();
        std::fs::write(
            &path,
            format!(
                "{top}\n[tls]\nca = \"{ca}\"\ncertificate = \"{file}.pem\"\nkey = \"{file}.key\"\n\n{rules}"
            ),
        )
        .expect("write the security file");
        path
    }
}

/// The rules every node of the test reads: the operator `ops` may command the robot's
/// base and what is inside it, nothing else.
const RULES: &str = "[[allow]]\nnodes = [\"ops\"]\ncommand = [\"robot/robot.base.*\"]\n";

/// `coolctl --config FILE ARGS` reaching `endpoint` only.
fn coolctl(config: &Path, endpoint: &str, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_coolctl"))
        .arg("--config")
        .arg(config)
        .args(["--connect", endpoint, "--no-multicast", "--timeout", "1s"])
        .args(args)
        .output()
        .expect("coolctl runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn tls_and_access_rules() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let dir = dir.path();
    let authority = Authority::new(dir, "fleet");
    let robot_file = authority.node(dir, "robot", "robot", RULES);
    let ops_file = authority.node(dir, "ops", "ops", RULES);
    // Another CA's certificate, with the operator's name.
    let intruder_file = Authority::new(dir, "other").node(dir, "intruder", "ops", RULES);

    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let security = Security::load(&robot_file).expect("the robot's security file");
    assert!(security.has_tls() && security.has_rules());
    let config = secure_config(std::slice::from_ref(&endpoint), &[], false, &security)
        .expect("a TLS configuration");
    // A node opens under its certificate's common name, no other.
    let other = secure_config(&[], &[], false, &security).expect("a TLS configuration");
    let error = Node::open("station", other).expect_err("not station's certificate");
    assert!(
        error
            .to_string()
            .contains("the certificate is node `robot`'s"),
        "{error}"
    );
    let node = Node::open("robot", config).expect("the robot's node opens");
    let system = robot(&node);
    let state = |path: &str| system.handle_at(path).expect(path).snapshot().state;

    // Allowed: the operator suspends the base's motion (the first run may come before
    // the TLS session is up: poll).
    let mut last = None;
    assert!(
        wait_until(PATIENCE, || {
            let out = coolctl(
                &ops_file,
                &endpoint,
                &["set", "robot/robot.base.motion", "state", "suspended"],
            );
            let ok = out.status.success();
            last = Some(out);
            ok
        }),
        "the allowed command never succeeded: {last:?}"
    );
    assert!(
        wait_until(PATIENCE, || state("robot.base.motion") == State::Suspended),
        "motion is {:?}",
        state("robot.base.motion")
    );

    // Outside the rules: the robot's access control drops the command; coolctl
    // fails with a clear error and the logger is untouched. The operator still sees
    // the logger (observing is open to every node of the CA).
    let out = coolctl(
        &ops_file,
        &endpoint,
        &["set", "robot/logger", "state", "suspended"],
    );
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let error = text(&out.stderr);
    assert!(
        error.contains("no component answered at `robot/logger`")
            && error.contains("do not let `ops` command `robot/logger`"),
        "{error}"
    );
    assert_eq!(state("logger"), State::Running);
    let listed = coolctl(&ops_file, &endpoint, &["list", "robot"]);
    assert!(listed.status.success(), "{listed:?}");
    assert!(
        text(&listed.stdout).contains("logger"),
        "{}",
        text(&listed.stdout)
    );

    // A certificate from another CA: the TLS handshake fails, the intruder sees no
    // node and its command does nothing.
    let out = coolctl(&intruder_file, &endpoint, &["nodes"]);
    assert!(!text(&out.stdout).contains("robot"), "{out:?}");
    let out = coolctl(
        &intruder_file,
        &endpoint,
        &["set", "robot/robot.base.ranges", "state", "suspended"],
    );
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    assert!(
        text(&out.stderr).contains("no node `robot`"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(state("robot.base.ranges"), State::Running);
    drop(system);
    drop(node);
}

#[test]
fn plaintext_off_loopback_is_refused_without_the_flag() {
    let out = Command::new(env!("CARGO_BIN_EXE_coolctl"))
        .args(["--connect", "tcp/192.0.2.1:7447", "--no-multicast", "nodes"])
        .output()
        .expect("coolctl runs");
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let error = text(&out.stderr);
    assert!(
        error.starts_with("coolctl: security: `tcp/192.0.2.1:7447` is not on loopback and not TLS")
            && error.contains("--insecure"),
        "{error}"
    );
    // Without TLS, multicast scouting is off unless asked for; asked for, it needs
    // --insecure.
    let out = Command::new(env!("CARGO_BIN_EXE_coolctl"))
        .args(["--multicast", "nodes"])
        .output()
        .expect("coolctl runs");
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert!(text(&out.stderr).contains("multicast scouting"), "{out:?}");
    let out = Command::new(env!("CARGO_BIN_EXE_coolctl"))
        .args(["--timeout", "200ms", "nodes"])
        .output()
        .expect("coolctl runs");
    assert_eq!(out.status.code(), Some(0), "{out:?}");
}
