//! `coolc diagram`: every view of every fixture and example, snapshotted as DOT and
//! as Markdown with mermaid; every emitted DOT text parses (a DOT parser below, and
//! Graphviz's `dot` too when it is installed) with every edge end, port and cluster
//! declared; every mermaid text is well formed; and the command's errors.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use coolc::diagram::{self, Format, Options, View};

fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .canonicalize()
        .expect("repository")
}

/// Analyzes `path` with paths shown relative to the repository; panics on errors.
fn analyze(path: &Path) -> coolc::Checked {
    let base = repository();
    let relative = path
        .canonicalize()
        .expect("fixture")
        .strip_prefix(&base)
        .expect("inside the repository")
        .to_owned();
    coolc::analyze(&[relative], &|p: &Path| {
        std::fs::read_to_string(base.join(p))
    })
    .checked()
    .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())))
}

/// Every view of every component of the file, with and without the default
/// automaton around automata.
fn all_diagrams(path: &Path) -> Vec<diagram::Diagram> {
    let checked = analyze(path);
    let mut diagrams = match diagram::diagrams(&checked, 1, &Options::default()) {
        Ok(diagrams) => diagrams,
        // A file of packets only (`types.cool`): nothing to draw.
        Err(diagram::SelectError::Nothing) => return Vec::new(),
        Err(error) => panic!("{}: {error}", path.display()),
    };
    let nested = Options {
        views: vec![View::Automaton],
        default_automaton: true,
        ..Options::default()
    };
    diagrams.extend(diagram::diagrams(&checked, 1, &nested).expect("draw nested"));
    diagrams
}

/// Every description that checks without errors: the ok and warn fixtures and the
/// examples.
fn each_description(mut check: impl FnMut(&Path)) {
    insta::glob!("../../tests/data", "ok/*.cool", |path| check(path));
    insta::glob!("../../tests/data", "warn/*.cool", |path| check(path));
    insta::glob!("../../examples/components", "*.cool", |path| check(path));
}

/// Every diagram of the file in `format`, if it has components.
fn rendered(path: &Path, format: Format) -> Option<String> {
    let diagrams = all_diagrams(path);
    (!diagrams.is_empty()).then(|| diagram::render(&diagrams, format).expect("render"))
}

// The two globs name their snapshots after the file, so each directory has its own
// test (snapshot names come from the test's name).

#[test]
fn dot_snapshots_of_the_fixtures() {
    insta::glob!("../../tests/data", "ok/*.cool", |path| {
        if let Some(text) = rendered(path, Format::Dot) {
            insta::assert_snapshot!(text);
        }
    });
}

#[test]
fn dot_snapshots_of_the_examples() {
    insta::glob!("../../examples/components", "*.cool", |path| {
        if let Some(text) = rendered(path, Format::Dot) {
            insta::assert_snapshot!(text);
        }
    });
}

#[test]
fn mermaid_snapshots_of_the_fixtures() {
    insta::glob!("../../tests/data", "ok/*.cool", |path| {
        if let Some(text) = rendered(path, Format::Markdown) {
            insta::assert_snapshot!(text);
        }
    });
}

#[test]
fn mermaid_snapshots_of_the_examples() {
    insta::glob!("../../examples/components", "*.cool", |path| {
        if let Some(text) = rendered(path, Format::Markdown) {
            insta::assert_snapshot!(text);
        }
    });
}

#[test]
fn every_dot_text_parses_with_its_ends_declared() {
    let dot_installed = Command::new("dot").arg("-V").output().is_ok();
    each_description(|path| {
        for one in all_diagrams(path) {
            let text = diagram::render(std::slice::from_ref(&one), Format::Dot).expect("dot");
            if let Err(error) = dot::check(&text) {
                panic!("{}: {}: {error}\n{text}", path.display(), one.title());
            }
            if dot_installed {
                let out = run_with_input("dot", &["-Tsvg"], &text);
                let stderr = String::from_utf8_lossy(&out.stderr);
                // Any complaint but a missing font is a diagram bug (a syntax error,
                // an edge dot cannot lay out).
                let complaints: Vec<&str> = stderr
                    .lines()
                    .filter(|line| !line.to_lowercase().contains("font"))
                    .collect();
                assert!(
                    out.status.success() && complaints.is_empty(),
                    "{}: dot says: {stderr}",
                    one.title()
                );
            }
        }
    });
}

#[test]
fn every_mermaid_text_is_well_formed() {
    each_description(|path| {
        for one in all_diagrams(path) {
            let text = diagram::render(std::slice::from_ref(&one), Format::Mermaid).expect("one");
            if let Err(error) = mermaid::check(&text) {
                panic!("{}: {}: {error}\n{text}", path.display(), one.title());
            }
        }
    });
}

#[test]
fn the_checkers_catch_broken_text() {
    for broken in [
        "digraph \"a\" { \"x\" -> \"y\"; }",
        "digraph \"a\" { \"x\" [label=\"open]; }",
        "digraph \"a\" { \"x\" [label=<<TABLE><TR></TABLE>>]; }",
        "digraph \"a\" { \"x\" [label=<<TABLE><TR><TD PORT=\"p\">a</TD></TR></TABLE>>]; \"x\":\"q\" -> \"x\"; }",
        "digraph \"a\" { \"x\"; \"x\" -> \"x\" [lhead=\"cluster_none\"]; }",
        "digraph \"a\" { \"x\" [label=<a < b>]; }",
        "digraph \"a\" { \"x\" [label=\"a\"] }}",
    ] {
        assert!(dot::check(broken).is_err(), "accepted: {broken}");
    }
    assert!(
        dot::check(
            "digraph \"a\" { subgraph \"cluster_c\" { \"x\" [label=<<B>a&lt;b</B>>]; } \"x\" -> \"x\" [ltail=\"cluster_c\"]; }"
        )
        .is_ok()
    );
    for broken in [
        "flowchart LR\n  n0[\"a\"]\n  n0 --> n1\n",
        "flowchart LR\n  n0[\"a<b\"]\n",
        "flowchart LR\n  subgraph g0 [\"x\"]\n  n0[\"a\"]\n",
        "flowchart LR\n  n0[\"a \" b\"]\n",
    ] {
        assert!(mermaid::check(broken).is_err(), "accepted: {broken}");
    }
}

#[test]
fn output_is_deterministic() {
    let path = repository().join("tests/data/ok/every_construct.cool");
    let first = diagram::render(&all_diagrams(&path), Format::Dot).expect("dot");
    let second = diagram::render(&all_diagrams(&path), Format::Dot).expect("dot");
    assert_eq!(first, second);
}

// ---------------------------------------------------------------------------------
// The command line.

fn coolc(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_coolc"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("coolc runs")
}

fn run_with_input(program: &str, args: &[&str], input: &str) -> Output {
    use std::io::Write;
    let mut child = Command::new(program)
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(input.as_bytes())
        .expect("write");
    child.wait_with_output().expect("wait")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn the_command_draws_to_stdout_or_a_file() {
    let examples = repository().join("examples/components");
    let out = coolc(
        &[
            "diagram",
            "mobile_base.cool",
            "--component",
            "MobileBase",
            "--view",
            "structure",
        ],
        &examples,
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(
        stdout.starts_with("digraph \"MobileBase · structure\""),
        "{stdout}"
    );
    dot::check(&stdout).expect("parses");

    let dir = tempfile::tempdir().expect("temp");
    let file = dir.path().join("robot.md");
    let out = coolc(
        &[
            "diagram",
            examples.join("mobile_base.cool").to_str().expect("utf-8"),
            "--format",
            "markdown",
            "-o",
            file.to_str().expect("utf-8"),
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(out.stdout.is_empty());
    let written = std::fs::read_to_string(&file).expect("written");
    for heading in [
        "## MobileBase · interface",
        "## MobileBase · structure",
        "## MobileBase · automaton",
        "## Robot · structure",
    ] {
        assert!(written.contains(heading), "{heading} missing");
    }
    assert!(
        !written.contains("## MotionController"),
        "imports are not drawn unless asked"
    );
}

#[test]
fn the_command_has_help() {
    let dir = tempfile::tempdir().expect("temp");
    let out = coolc(&["--help"], dir.path());
    assert!(
        text(&out.stdout).contains("diagram"),
        "{}",
        text(&out.stdout)
    );
    let out = coolc(&["diagram", "--help"], dir.path());
    assert_eq!(out.status.code(), Some(0));
    let help = text(&out.stdout);
    for option in [
        "--component",
        "--view",
        "interface",
        "structure",
        "automaton",
        "--format",
        "mermaid",
        "markdown",
        "--default-automaton",
        "--output",
    ] {
        assert!(help.contains(option), "{option} missing from:\n{help}");
    }
}

#[test]
fn the_command_reports_what_it_cannot_draw() {
    let examples = repository().join("examples/components");
    let out = coolc(
        &["diagram", "mobile_base.cool", "--component", "Nobody"],
        &examples,
    );
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("no component named `Nobody`") && stderr.contains("MobileBase"),
        "{stderr}"
    );

    let out = coolc(
        &[
            "diagram",
            "motion_controller.cool",
            "--component",
            "MotionController",
            "--view",
            "structure",
        ],
        &examples,
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("is atomic"),
        "{}",
        text(&out.stderr)
    );

    let out = coolc(
        &["diagram", "mobile_base.cool", "--format", "mermaid"],
        &examples,
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("--format markdown"),
        "{}",
        text(&out.stderr)
    );

    let out = coolc(&["diagram", "types.cool"], &examples);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("no component"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn a_description_with_errors_is_not_drawn() {
    let dir = tempfile::tempdir().expect("temp");
    std::fs::write(
        dir.path().join("broken.cool"),
        "atomic Broken {\n    input x: fifo<Nothing>(4);\n}\n",
    )
    .expect("write");
    let out = coolc(&["diagram", "broken.cool"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty(), "nothing drawn");
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("unknown_type") && stderr.contains("1 error(s)"),
        "{stderr}"
    );
}

// ---------------------------------------------------------------------------------
// A DOT parser: the subset of the DOT grammar (https://graphviz.org/doc/info/lang.html)
// coolc writes, strictly: quoted ids, HTML strings, attribute lists, node, edge and
// attribute statements, subgraphs. It also checks what `dot` would only draw wrongly:
// edges between declared nodes, declared ports, clusters named by lhead/ltail.

mod dot {
    use super::*;

    #[derive(Debug, Clone, PartialEq)]
    enum Token {
        /// A quoted string, unescaped (`\"` to `"`; other escapes kept).
        Quoted(String),
        /// A bare id (keywords, numbers, simple names).
        Bare(String),
        /// An HTML string, without its outer `<` `>`.
        Html(String),
        Punct(char),
        Arrow,
    }

    fn tokens(text: &str) -> Result<Vec<Token>, String> {
        let chars: Vec<char> = text.chars().collect();
        let mut out = Vec::new();
        let mut i = 0;
        while i < chars.len() {
            let c = chars[i];
            if c.is_whitespace() {
                i += 1;
            } else if c == '"' {
                let mut value = String::new();
                i += 1;
                loop {
                    match chars.get(i) {
                        None => return Err("unterminated string".to_owned()),
                        Some('"') => break,
                        Some('\\') => {
                            match chars.get(i + 1) {
                                Some('"') => value.push('"'),
                                Some(other) => {
                                    value.push('\\');
                                    value.push(*other);
                                }
                                None => return Err("unterminated string".to_owned()),
                            }
                            i += 2;
                            continue;
                        }
                        Some('\n') => return Err("a newline inside a string".to_owned()),
                        Some(other) => value.push(*other),
                    }
                    i += 1;
                }
                i += 1;
                out.push(Token::Quoted(value));
            } else if c == '<' {
                let mut depth = 0;
                let start = i;
                loop {
                    match chars.get(i) {
                        None => return Err("unterminated HTML string".to_owned()),
                        Some('<') => depth += 1,
                        Some('>') => {
                            depth -= 1;
                            if depth == 0 {
                                break;
                            }
                        }
                        _ => {}
                    }
                    i += 1;
                }
                out.push(Token::Html(chars[start + 1..i].iter().collect()));
                i += 1;
            } else if c == '-' && chars.get(i + 1) == Some(&'>') {
                out.push(Token::Arrow);
                i += 2;
            } else if "{}[];,=:".contains(c) {
                out.push(Token::Punct(c));
                i += 1;
            } else if c.is_alphanumeric() || c == '_' || c == '.' {
                let start = i;
                while i < chars.len() && (chars[i].is_alphanumeric() || "_.".contains(chars[i])) {
                    i += 1;
                }
                out.push(Token::Bare(chars[start..i].iter().collect()));
            } else {
                return Err(format!("unexpected character {c:?}"));
            }
        }
        Ok(out)
    }

    #[derive(Default)]
    struct Graph {
        /// Node id and the ports its HTML label declares.
        nodes: Vec<(String, BTreeSet<String>)>,
        clusters: BTreeSet<String>,
        /// `(node, port)` of each edge end, and the clusters lhead/ltail name.
        ends: Vec<(String, Option<String>)>,
        clipped: Vec<String>,
    }

    struct Parser {
        tokens: Vec<Token>,
        at: usize,
        graph: Graph,
    }

    impl Parser {
        fn peek(&self) -> Option<&Token> {
            self.tokens.get(self.at)
        }

        fn next(&mut self) -> Result<Token, String> {
            let token = self.tokens.get(self.at).cloned().ok_or("unexpected end")?;
            self.at += 1;
            Ok(token)
        }

        fn punct(&mut self, c: char) -> Result<(), String> {
            match self.next()? {
                Token::Punct(found) if found == c => Ok(()),
                other => Err(format!("expected {c:?}, found {other:?}")),
            }
        }

        fn id(&mut self) -> Result<String, String> {
            match self.next()? {
                Token::Quoted(value) | Token::Bare(value) => Ok(value),
                other => Err(format!("expected an id, found {other:?}")),
            }
        }

        fn graph(&mut self) -> Result<(), String> {
            match self.next()? {
                Token::Bare(keyword) if keyword == "digraph" => {}
                other => return Err(format!("expected digraph, found {other:?}")),
            }
            self.id()?;
            self.block()?;
            if self.at != self.tokens.len() {
                return Err(format!("text after the graph: {:?}", self.peek()));
            }
            Ok(())
        }

        fn block(&mut self) -> Result<(), String> {
            self.punct('{')?;
            loop {
                match self.peek() {
                    Some(Token::Punct('}')) => {
                        self.at += 1;
                        return Ok(());
                    }
                    None => return Err("unclosed {".to_owned()),
                    _ => self.statement()?,
                }
            }
        }

        fn statement(&mut self) -> Result<(), String> {
            if let Some(Token::Bare(keyword)) = self.peek() {
                match keyword.as_str() {
                    "graph" | "node" | "edge" => {
                        self.at += 1;
                        self.attributes()?;
                        return self.punct(';');
                    }
                    "subgraph" => {
                        self.at += 1;
                        let name = self.id()?;
                        if !name.starts_with("cluster") {
                            return Err(format!("subgraph {name} is not a cluster"));
                        }
                        self.graph.clusters.insert(name);
                        return self.block();
                    }
                    _ => {}
                }
            }
            let (node, port) = self.node_id()?;
            if let Some(Token::Arrow) = self.peek() {
                self.graph.ends.push((node, port));
                while let Some(Token::Arrow) = self.peek() {
                    self.at += 1;
                    let end = self.node_id()?;
                    self.graph.ends.push(end);
                }
                let attributes = self.attributes_opt()?;
                for (name, value) in attributes {
                    if name == "lhead" || name == "ltail" {
                        self.graph.clipped.push(value);
                    }
                }
            } else {
                if port.is_some() {
                    return Err("a port on a node statement".to_owned());
                }
                let attributes = self.attributes_opt()?;
                let mut ports = BTreeSet::new();
                for (name, value) in attributes {
                    if name == "label" && value.starts_with('<') {
                        ports = html(&value[1..value.len() - 1])?;
                    } else if name == "label" {
                        label(&value)?;
                    }
                }
                self.graph.nodes.push((node, ports));
            }
            self.punct(';')
        }

        fn node_id(&mut self) -> Result<(String, Option<String>), String> {
            let node = self.id()?;
            let mut port = None;
            if let Some(Token::Punct(':')) = self.peek() {
                self.at += 1;
                port = Some(self.id()?);
                if let Some(Token::Punct(':')) = self.peek() {
                    self.at += 1;
                    let compass = self.id()?;
                    if !["n", "ne", "e", "se", "s", "sw", "w", "nw", "c", "_"]
                        .contains(&compass.as_str())
                    {
                        return Err(format!("bad compass point {compass}"));
                    }
                }
            }
            Ok((node, port))
        }

        fn attributes_opt(&mut self) -> Result<Vec<(String, String)>, String> {
            if let Some(Token::Punct('[')) = self.peek() {
                self.attributes()
            } else {
                Ok(Vec::new())
            }
        }

        fn attributes(&mut self) -> Result<Vec<(String, String)>, String> {
            self.punct('[')?;
            let mut out = Vec::new();
            loop {
                if let Some(Token::Punct(']')) = self.peek() {
                    self.at += 1;
                    return Ok(out);
                }
                let name = self.id()?;
                self.punct('=')?;
                let value = match self.next()? {
                    Token::Quoted(value) | Token::Bare(value) => value,
                    Token::Html(value) => format!("<{value}>"),
                    other => return Err(format!("bad attribute value {other:?}")),
                };
                out.push((name, value));
                if let Some(Token::Punct(',' | ';')) = self.peek() {
                    self.at += 1;
                }
            }
        }
    }

    /// A plain label: backslash escapes are the ones Graphviz knows.
    fn label(value: &str) -> Result<(), String> {
        let mut chars = value.chars();
        while let Some(c) = chars.next() {
            if c == '\\' {
                match chars.next() {
                    Some('\\' | 'n' | 'l' | 'r' | '"') => {}
                    other => return Err(format!("label escape \\{other:?} in {value:?}")),
                }
            }
        }
        Ok(())
    }

    /// An HTML-like label: tags balanced, entities known, no stray `<` `>`; returns
    /// the PORT names.
    fn html(value: &str) -> Result<BTreeSet<String>, String> {
        let mut stack: Vec<String> = Vec::new();
        let mut ports = BTreeSet::new();
        let mut rest = value;
        while let Some(position) = rest.find(['<', '>', '&']) {
            let after = &rest[position..];
            if after.starts_with('>') {
                return Err(format!("a stray > in {value:?}"));
            }
            if let Some(entity) = after.strip_prefix('&') {
                let end = entity.find(';').ok_or("an unterminated entity")?;
                if !["lt", "gt", "amp", "quot"].contains(&&entity[..end]) {
                    return Err(format!("unknown entity &{};", &entity[..end]));
                }
                rest = &entity[end + 1..];
                continue;
            }
            let end = after.find('>').ok_or("an unterminated tag")?;
            let tag = &after[1..end];
            rest = &after[end + 1..];
            if tag.contains('<') {
                return Err(format!("a stray < in {value:?}"));
            }
            if let Some(name) = tag.strip_prefix('/') {
                match stack.pop() {
                    Some(open) if open == name => {}
                    other => return Err(format!("</{name}> closes {other:?}")),
                }
                continue;
            }
            let self_closing = tag.ends_with('/');
            let tag = tag.trim_end_matches('/');
            let mut words = tag.split_whitespace();
            let name = words.next().ok_or("an empty tag")?.to_owned();
            if !["TABLE", "TR", "TD", "B", "BR", "FONT", "I"].contains(&name.as_str()) {
                return Err(format!("unknown tag {name}"));
            }
            for attribute in tag[name.len()..].split('"').collect::<Vec<_>>().chunks(2) {
                if let [key, value] = attribute
                    && key.trim().trim_end_matches('=') == "PORT"
                {
                    ports.insert((*value).to_owned());
                }
            }
            if !self_closing {
                stack.push(name);
            }
        }
        if !stack.is_empty() {
            return Err(format!("unclosed tags {stack:?}"));
        }
        Ok(ports)
    }

    /// Parses one `digraph` and checks its references.
    pub fn check(text: &str) -> Result<(), String> {
        let mut texts = Vec::new();
        for (i, part) in text.split("\ndigraph ").enumerate() {
            texts.push(if i == 0 {
                part.to_owned()
            } else {
                format!("digraph {part}")
            });
        }
        for text in texts {
            let mut parser = Parser {
                tokens: tokens(&text)?,
                at: 0,
                graph: Graph::default(),
            };
            parser.graph()?;
            let graph = parser.graph;
            for (node, port) in &graph.ends {
                let Some((_, ports)) = graph.nodes.iter().find(|(id, _)| id == node) else {
                    return Err(format!("edge end {node} is not declared"));
                };
                if let Some(port) = port
                    && !ports.contains(port)
                {
                    return Err(format!("{node} has no port {port} ({ports:?})"));
                }
            }
            for cluster in &graph.clipped {
                if !graph.clusters.contains(cluster) {
                    return Err(format!("no cluster {cluster}"));
                }
            }
            let mut seen = BTreeSet::new();
            for (node, _) in &graph.nodes {
                if !seen.insert(node) {
                    return Err(format!("{node} declared twice"));
                }
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------
// Mermaid: the flowchart subset coolc writes.

mod mermaid {
    use super::*;

    /// A quoted label: no raw `"`, `<`, `>` or `|` except the line breaks coolc writes.
    fn label(text: &str) -> Result<(), String> {
        let inner = text
            .strip_prefix('"')
            .and_then(|t| t.strip_suffix('"'))
            .ok_or_else(|| format!("unquoted label {text}"))?;
        let bare = inner.replace("<br/>", "");
        if bare.contains(['"', '<', '>', '|']) {
            return Err(format!("unescaped text in {text}"));
        }
        Ok(())
    }

    pub fn check(text: &str) -> Result<(), String> {
        let mut lines = text.lines();
        let header = lines.next().ok_or("empty")?;
        if !header.starts_with("%% ") {
            return Err("no title comment".to_owned());
        }
        match lines.next() {
            Some("flowchart LR" | "flowchart TB") => {}
            other => return Err(format!("not a flowchart: {other:?}")),
        }
        let mut declared = BTreeSet::new();
        let mut depth = 0usize;
        let mut used = Vec::new();
        for line in lines {
            let line = line.trim();
            if let Some(rest) = line.strip_prefix("subgraph ") {
                let (id, title) = rest.split_once(' ').ok_or("a subgraph without a title")?;
                let title = title
                    .strip_prefix('[')
                    .and_then(|t| t.strip_suffix(']'))
                    .ok_or("a subgraph title not in brackets")?;
                label(title)?;
                declared.insert(id.to_owned());
                depth += 1;
            } else if line == "end" {
                depth = depth.checked_sub(1).ok_or("end without subgraph")?;
            } else if line.starts_with("classDef ") {
            } else if let Some(rest) = line.strip_prefix("class ") {
                let id = rest.split(' ').next().unwrap_or_default();
                used.push(id.to_owned());
            } else if let Some((from, rest)) =
                line.split_once(" -->").or_else(|| line.split_once(" -.->"))
            {
                used.push(from.to_owned());
                let rest = rest.trim();
                let to = if let Some(labelled) = rest.strip_prefix('|') {
                    let (text, to) = labelled.split_once("| ").ok_or("an unclosed edge label")?;
                    label(text)?;
                    to
                } else {
                    rest
                };
                used.push(to.trim().to_owned());
            } else {
                let split = line
                    .find(['[', '(', '>'])
                    .ok_or_else(|| format!("not a node: {line}"))?;
                let (id, shape) = line.split_at(split);
                let inner = ["([", "((", "[", "(", ">"]
                    .iter()
                    .find_map(|open| {
                        let close = match *open {
                            "([" => "])",
                            "((" => "))",
                            "[" | ">" => "]",
                            _ => ")",
                        };
                        shape.strip_prefix(open).and_then(|s| s.strip_suffix(close))
                    })
                    .ok_or_else(|| format!("unknown shape: {line}"))?;
                label(inner)?;
                if !declared.insert(id.to_owned()) {
                    return Err(format!("{id} declared twice"));
                }
            }
        }
        if depth != 0 {
            return Err("unclosed subgraph".to_owned());
        }
        for id in used {
            if !declared.contains(&id) {
                return Err(format!("{id} is used but not declared"));
            }
        }
        Ok(())
    }
}

/// `on "node"` runs the instance on that node when the process is on a network
/// (`docs/distribution.md`), so the structure view labels it with its node and says
/// when; it is not drawn dashed (dashed is for substitutes and redundant groups).
#[test]
fn an_instance_on_a_node_is_labelled_with_its_node() {
    let path = repository().join("examples/components/mobile_base.cool");
    let dot = rendered(&path, Format::Dot).expect("a compound to draw");
    assert!(
        dot.contains("on &quot;station&quot; (remote when on a network)"),
        "{dot}"
    );
    let wanderer = dot
        .lines()
        .find(|line| line.trim_start().starts_with("\"wanderer\""))
        .expect("the wanderer node");
    assert!(!wanderer.contains("dashed"), "{wanderer}");
}
