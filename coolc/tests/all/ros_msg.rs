//! The `.msg` reader (`coolc::ros`): every feature of the format, every diagnostic
//! with its span, where types are looked up, and the type descriptions hashed.
//! Hashes are checked against an implementation we did not write in `ros_rosbags.rs`.

use std::collections::BTreeMap;
use std::io;
use std::path::{Path, PathBuf};

use coolc::ast::Span;
use coolc::diagnostics::{Code, Diagnostic, Severity};
use coolc::ros::description::type_id;
use coolc::ros::msg::{Base, Cardinality, FieldType, Value};
use coolc::ros::{Interfaces, Message, Search, TypeName, Wanted, load, parse::parse};
use coolc::{RenderOptions, SourceMap};

/// Parses `text` as the file of `name`: the sources (one file), the message and the
/// diagnostics.
fn read(name: &str, text: &str) -> (SourceMap, Message, Vec<Diagnostic>) {
    let name = TypeName::parse(name).unwrap();
    let mut sources = SourceMap::new();
    let file = sources.add(name.relative_path(), text);
    let (message, diagnostics) = parse(&name, file, text);
    (sources, message, diagnostics)
}

/// Parses a file that must be clean.
fn clean(text: &str) -> Message {
    let (sources, message, diagnostics) = read("my_msgs/msg/Test", text);
    assert!(
        diagnostics.is_empty(),
        "{}",
        coolc::diagnostics::render(&sources, &diagnostics, RenderOptions::plain())
    );
    message
}

/// The one diagnostic of a bad file: its code, and the text its primary span covers.
fn one_error(text: &str) -> (Code, String, Diagnostic) {
    let (_, _, diagnostics) = read("my_msgs/msg/Test", text);
    assert_eq!(diagnostics.len(), 1, "{text:?}: {diagnostics:#?}");
    let diagnostic = diagnostics.into_iter().next().unwrap();
    assert_eq!(diagnostic.severity, Severity::Error);
    let span = diagnostic.primary_span();
    (
        diagnostic.code,
        text[span.start..span.end].to_owned(),
        diagnostic,
    )
}

fn ty(base: Base, cardinality: Cardinality) -> FieldType {
    FieldType { base, cardinality }
}

fn name(full: &str) -> TypeName {
    TypeName::parse(full).unwrap()
}

#[test]
fn every_primitive_type_reads() {
    let keywords = [
        "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
        "uint64", "float32", "float64", "string", "wstring",
    ];
    let text: String = keywords
        .iter()
        .enumerate()
        .map(|(i, keyword)| format!("{keyword} f{i}\n"))
        .collect();
    let message = clean(&text);
    let read: Vec<String> = message.fields.iter().map(|f| f.ty.to_string()).collect();
    assert_eq!(read, keywords);
    assert_eq!(message.fields[2].ty.base, Base::Char);
    assert_eq!(message.fields[14].ty.base, Base::WString(None));
    assert_eq!(message.fields[14].name, "f14");
}

#[test]
fn bounded_strings_and_every_array_form_read() {
    let message = clean(
        "string<=8 a\nwstring<=3 b\nint32[4] c\nfloat64[<=5] d\nuint8[] e\nstring<=5[<=3] f\nstring[2] g\n",
    );
    let types: Vec<FieldType> = message.fields.iter().map(|f| f.ty.clone()).collect();
    assert_eq!(
        types,
        [
            ty(Base::String(Some(8)), Cardinality::Single),
            ty(Base::WString(Some(3)), Cardinality::Single),
            ty(Base::Int32, Cardinality::Array(4)),
            ty(Base::Float64, Cardinality::Bounded(5)),
            ty(Base::Uint8, Cardinality::Unbounded),
            ty(Base::String(Some(5)), Cardinality::Bounded(3)),
            ty(Base::String(None), Cardinality::Array(2)),
        ]
    );
}

#[test]
fn nested_types_name_this_package_or_another() {
    let (_, message, diagnostics) = read(
        "geometry_msgs/msg/Thing",
        "Point p\nstd_msgs/Header header\nPose[] poses\nbuiltin_interfaces/Time[<=2] times\n",
    );
    assert!(diagnostics.is_empty(), "{diagnostics:#?}");
    let bases: Vec<String> = message.fields.iter().map(|f| f.ty.to_string()).collect();
    assert_eq!(
        bases,
        [
            "geometry_msgs/msg/Point",
            "std_msgs/msg/Header",
            "geometry_msgs/msg/Pose[]",
            "builtin_interfaces/msg/Time[<=2]",
        ]
    );
}

#[test]
fn constants_read_with_their_values() {
    let message = clean(concat!(
        "uint8 MODE_SLOW=0\n",
        "uint8 MODE_FAST = 0x1F   # hex, blanks around `=`\n",
        "int64 LOW=-9223372036854775808\n",
        "float64 PI=3.5\n",
        "bool ON=True\n",
        "string NAME=\"a # b\"  # the first `#` is in the string\n",
        "string PLAIN=two words\n",
        "string QUOTED='say \\'hi\\''\n",
        "char C=65\n",
    ));
    let constants: Vec<(&str, &Base, &Value)> = message
        .constants
        .iter()
        .map(|c| (c.name.as_str(), &c.ty, &c.value))
        .collect();
    assert_eq!(
        constants,
        [
            ("MODE_SLOW", &Base::Uint8, &Value::Int(0)),
            ("MODE_FAST", &Base::Uint8, &Value::Int(31)),
            ("LOW", &Base::Int64, &Value::Int(i128::from(i64::MIN))),
            ("PI", &Base::Float64, &Value::Float(3.5)),
            ("ON", &Base::Bool, &Value::Bool(true)),
            ("NAME", &Base::String(None), &Value::String("a # b".into())),
            (
                "PLAIN",
                &Base::String(None),
                &Value::String("two words".into())
            ),
            (
                "QUOTED",
                &Base::String(None),
                &Value::String("say 'hi'".into())
            ),
            ("C", &Base::Char, &Value::Int(65)),
        ]
    );
    assert!(message.fields.is_empty());
}

#[test]
fn defaults_read_for_scalars_and_arrays() {
    let text = concat!(
        "float64 x 1.0\n",
        "int32 n -3\n",
        "bool b false\n",
        "string s \"with, comma\"\n",
        "string<=5 t short\n",
        "int32[] a [1,2]\n",
        "float32[3] v [1.5, -2, 3e2]\n",
        "int8[<=4] few []\n",
        "string[] words [\"a,b\", 'c', d]\n",
        "float64 far -inf\n",
    );
    let message = clean(text);
    let defaults: Vec<(&str, Value)> = message
        .fields
        .iter()
        .map(|f| (f.name.as_str(), f.default.clone().unwrap().0))
        .collect();
    let ints = |v: &[i128]| Value::Array(v.iter().map(|i| Value::Int(*i)).collect());
    let strings = |v: &[&str]| Value::Array(v.iter().map(|s| Value::String((*s).into())).collect());
    assert_eq!(
        defaults,
        [
            ("x", Value::Float(1.0)),
            ("n", Value::Int(-3)),
            ("b", Value::Bool(false)),
            ("s", Value::String("with, comma".into())),
            ("t", Value::String("short".into())),
            ("a", ints(&[1, 2])),
            (
                "v",
                Value::Array(vec![
                    Value::Float(1.5),
                    Value::Float(-2.0),
                    Value::Float(300.0)
                ])
            ),
            ("few", Value::Array(vec![])),
            ("words", strings(&["a,b", "c", "d"])),
            ("far", Value::Float(f64::NEG_INFINITY)),
        ]
    );
    let span = message.fields[5].default.as_ref().unwrap().1;
    assert_eq!(&text[span.start..span.end], "[1,2]");
}

#[test]
fn comments_blank_lines_tabs_and_crlf_are_ignored() {
    let text =
        "# A file comment.\r\n\r\n\tint32\ta\t# trailing\r\n   # indented comment\nint32 b\n#";
    let message = clean(text);
    let fields: Vec<&str> = message.fields.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(fields, ["a", "b"]);
    let a = &message.fields[0];
    assert_eq!(&text[a.ty_span.start..a.ty_span.end], "int32");
    assert_eq!(&text[a.name_span.start..a.name_span.end], "a");
}

#[test]
fn spans_point_at_types_names_and_values() {
    let text = "uint8 FOO=1\nfloat64[3] v [1, 2, 3]\n";
    let message = clean(text);
    let cut = |span: Span| &text[span.start..span.end];
    let constant = &message.constants[0];
    assert_eq!(
        (
            cut(constant.ty_span),
            cut(constant.name_span),
            cut(constant.value_span)
        ),
        ("uint8", "FOO", "1")
    );
    let field = &message.fields[0];
    assert_eq!(
        (cut(field.ty_span), cut(field.name_span)),
        ("float64[3]", "v")
    );
}

/// Every diagnostic: (file text, expected code, the text its primary span covers).
#[rustfmt::skip]
const BAD: &[(&str, Code, &str)] = &[
    // Types.
    ("float x\n", Code::UnknownType, "float"),
    ("time t\n", Code::UnknownType, "time"),
    ("geometry_msgs/msg/Point p\n", Code::UnknownType, "geometry_msgs/msg/Point"),
    ("Geometry/Point p\n", Code::UnknownType, "Geometry/Point"),
    ("geometry_msgs/point p\n", Code::UnknownType, "geometry_msgs/point"),
    ("a/b/c/D p\n", Code::UnknownType, "a/b/c/D"),
    ("[3] p\n", Code::UnexpectedToken, ""),
    ("int32 \n", Code::UnexpectedToken, "int32"),
    ("int32[0] a\n", Code::ZeroSize, "0"),
    ("int32[<=0] a\n", Code::ZeroSize, "0"),
    ("string<=0 s\n", Code::ZeroSize, "0"),
    ("int32[x] a\n", Code::InvalidNumber, "x"),
    ("int32[99999999999999999999] a\n", Code::InvalidNumber, "99999999999999999999"),
    ("string<=x s\n", Code::InvalidNumber, "x"),
    ("int32[3 a\n", Code::UnexpectedToken, "[3"),
    ("int32[2][3] a\n", Code::UnexpectedToken, "[2][3]"),
    // Names.
    ("int32 Speed\n", Code::Naming, "Speed"),
    ("int32 max__speed\n", Code::Naming, "max__speed"),
    ("int32 speed_\n", Code::Naming, "speed_"),
    ("int32 lower=1\n", Code::Naming, "lower"),
    ("int32 =1\n", Code::UnexpectedToken, "="),
    // Defaults.
    ("int32 a x\n", Code::TypeMismatch, "x"),
    ("int32 a 1.5\n", Code::TypeMismatch, "1.5"),
    ("uint8 a 256\n", Code::InvalidNumber, "256"),
    ("int8 a -129\n", Code::InvalidNumber, "-129"),
    ("byte a -1\n", Code::InvalidNumber, "-1"),
    ("float32 a 1e39\n", Code::InvalidNumber, "1e39"),
    ("float32[] a [1.0, -3.5e38]\n", Code::InvalidNumber, "-3.5e38"),
    ("bool b yes\n", Code::TypeMismatch, "yes"),
    ("float64 f 1,5\n", Code::TypeMismatch, "1,5"),
    ("string<=3 s \"abcd\"\n", Code::TypeMismatch, "\"abcd\""),
    ("string s \"a\"b\"\n", Code::TypeMismatch, "\"a\"b\""),
    ("int32[] a 1\n", Code::TypeMismatch, "1"),
    ("int32[2] a [1]\n", Code::TypeMismatch, "[1]"),
    ("int32[<=1] a [1, 2]\n", Code::TypeMismatch, "[1, 2]"),
    ("int32[] a [1, x]\n", Code::TypeMismatch, "x"),
    ("string[] a [\"x\" y]\n", Code::UnexpectedToken, "y"),
    ("Point p 0\n", Code::MisplacedMember, "0"),
    ("Point[] p []\n", Code::MisplacedMember, "[]"),
    // Constants.
    ("int32[] A=1\n", Code::MisplacedMember, "int32[]"),
    ("Point P=1\n", Code::MisplacedMember, "Point"),
    ("string<=3 S=\"a\"\n", Code::MisplacedMember, "string<=3"),
    ("int32 A=\n", Code::UnexpectedToken, "="),
    ("uint8 A=300\n", Code::InvalidNumber, "300"),
    ("float32 A=1e39\n", Code::InvalidNumber, "1e39"),
    ("bool B=2\n", Code::TypeMismatch, "2"),
    // Duplicates (reported at the second).
    ("int32 a\nint32 b\nfloat64 a\n", Code::Duplicate, "a"),
    ("int32 A=1\nint32 A=2\n", Code::Duplicate, "A"),
];

#[test]
fn every_malformed_line_gets_a_diagnostic_at_its_span() {
    for (text, code, at) in BAD {
        let (found, covered, diagnostic) = one_error(text);
        assert_eq!(
            (found, covered.as_str()),
            (*code, *at),
            "{text:?}: {}",
            diagnostic.message
        );
    }
}

#[test]
fn a_duplicate_points_at_the_first_definition_too() {
    let text = "int32 a\nfloat64 a\n";
    let (_, _, diagnostic) = one_error(text);
    let first = diagnostic.labels[1].span;
    assert_eq!((first.start, first.end), (6, 7));
    assert_eq!(diagnostic.labels[1].message, "first defined here");
}

#[test]
fn helps_say_what_to_write() {
    let help = |text: &str| one_error(text).2.help.unwrap_or_default();
    assert_eq!(help("float x\n"), "did you mean `float32`?");
    assert!(help("time t\n").contains("builtin_interfaces/Time"));
    assert_eq!(
        help("geometry_msgs/msg/Point p\n"),
        "write `geometry_msgs/Point`"
    );
    assert!(help("int32 Speed\n").contains("lower snake case"));
    assert!(help("int32 lower=1\n").contains("upper snake case"));
}

#[test]
fn every_error_of_a_file_is_reported_and_bad_lines_add_nothing() {
    let (_, message, diagnostics) = read(
        "my_msgs/msg/Test",
        "int32 ok\nfloat bad_type\nint32 Bad\nint32 good 1\nuint8 X=999\n",
    );
    let codes: Vec<Code> = diagnostics.iter().map(|d| d.code).collect();
    assert_eq!(
        codes,
        [Code::UnknownType, Code::Naming, Code::InvalidNumber]
    );
    let fields: Vec<&str> = message.fields.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(fields, ["ok", "good"]);
    assert!(message.constants.is_empty());
}

#[test]
fn diagnostics_render_with_the_msg_file_and_line() {
    let (sources, _, diagnostics) = read("my_msgs/msg/Test", "int32 a\nint32 b 1.5\n");
    let text = coolc::diagnostics::render(&sources, &diagnostics, RenderOptions::plain());
    assert!(text.contains("coolc::check::type_mismatch"), "{text}");
    assert!(text.contains("my_msgs/msg/Test.msg:2:9"), "{text}");
    assert!(text.contains("int32 b 1.5"), "{text}");
}

/// A loader over in-memory files.
fn files(entries: &[(&str, &str)]) -> impl Fn(&Path) -> io::Result<String> + use<> {
    let map: BTreeMap<PathBuf, String> = entries
        .iter()
        .map(|(path, text)| (PathBuf::from(path), (*text).to_owned()))
        .collect();
    move |path: &Path| {
        map.get(path)
            .cloned()
            .ok_or_else(|| io::ErrorKind::NotFound.into())
    }
}

/// Loads `asked` (each named in a root file of its own) through `search`.
fn load_all(
    search: &Search,
    asked: &[&str],
    loader: &dyn Fn(&Path) -> io::Result<String>,
) -> (SourceMap, Interfaces) {
    let mut sources = SourceMap::new();
    let wanted: Vec<Wanted<'_>> = asked
        .iter()
        .map(|name| Wanted {
            name,
            file: sources.add(format!("{name}.cool"), *name),
            span: Span::new(0, name.len()),
        })
        .collect();
    let interfaces = load(search, &wanted, &mut sources, loader);
    (sources, interfaces)
}

fn loaded(interfaces: &Interfaces) -> Vec<String> {
    interfaces.messages().map(|m| m.name.to_string()).collect()
}

#[test]
fn shipped_types_load_with_everything_they_reference() {
    let (_, interfaces) = load_all(&Search::new(), &["nav_msgs/msg/Odometry"], &files(&[]));
    assert!(!interfaces.has_errors(), "{:#?}", interfaces.diagnostics);
    assert_eq!(
        loaded(&interfaces),
        [
            "builtin_interfaces/msg/Time",
            "geometry_msgs/msg/Point",
            "geometry_msgs/msg/Pose",
            "geometry_msgs/msg/PoseWithCovariance",
            "geometry_msgs/msg/Quaternion",
            "geometry_msgs/msg/Twist",
            "geometry_msgs/msg/TwistWithCovariance",
            "geometry_msgs/msg/Vector3",
            "nav_msgs/msg/Odometry",
            "std_msgs/msg/Header",
        ]
    );
    let quaternion = interfaces
        .get(&name("geometry_msgs/msg/Quaternion"))
        .unwrap();
    let w = &quaternion.fields[3];
    assert_eq!(
        (w.name.as_str(), &w.default.as_ref().unwrap().0),
        ("w", &Value::Float(1.0))
    );
}

#[test]
fn every_shipped_type_reads_cleanly() {
    let all: Vec<String> = coolc::ros::shipped::names()
        .map(|n| n.to_string())
        .collect();
    let asked: Vec<&str> = all.iter().map(String::as_str).collect();
    let (_, interfaces) = load_all(&Search::new(), &asked, &files(&[]));
    assert!(!interfaces.has_errors(), "{:#?}", interfaces.diagnostics);
    assert_eq!(loaded(&interfaces), all);
    assert_eq!(all.len(), 17);
}

#[test]
fn explicit_dirs_come_before_ament_prefixes_before_shipped() {
    let ament = std::env::join_paths(["/opt/ros", "/opt/other"]).unwrap();
    let search = Search::new()
        .with_dir("/first")
        .with_dir("/second")
        .with_ament_prefix_path(&ament);
    let loader = files(&[
        (
            "/second/my_msgs/msg/Thing.msg",
            "Part part\ngeometry_msgs/Point p\nstd_msgs/Header h\n",
        ),
        ("/first/my_msgs/msg/Part.msg", "int32 from_first\n"),
        ("/second/my_msgs/msg/Part.msg", "int32 from_second\n"),
        (
            "/opt/other/share/geometry_msgs/msg/Point.msg",
            "float64 from_other\n",
        ),
        (
            "/opt/ros/share/geometry_msgs/msg/Point.msg",
            "float64 from_ament\n",
        ),
    ]);
    let (sources, interfaces) = load_all(&search, &["my_msgs/msg/Thing"], &loader);
    assert!(!interfaces.has_errors(), "{:#?}", interfaces.diagnostics);
    let first_field = |full: &str| interfaces.get(&name(full)).unwrap().fields[0].name.clone();
    assert_eq!(first_field("my_msgs/msg/Part"), "from_first");
    assert_eq!(first_field("geometry_msgs/msg/Point"), "from_ament");
    assert_eq!(first_field("std_msgs/msg/Header"), "stamp");
    let header = interfaces.get(&name("std_msgs/msg/Header")).unwrap();
    assert_eq!(
        sources.display_path(header.file),
        "<shipped>/std_msgs/msg/Header.msg"
    );
}

#[test]
fn a_missing_type_is_reported_where_it_is_used_naming_every_place_searched() {
    let search = Search::new().with_dir("/msgs");
    let loader = files(&[(
        "/msgs/my_msgs/msg/Thing.msg",
        "int32 a\ngeometry_msgs/Pointt[] p\n",
    )]);
    let (sources, interfaces) = load_all(&search, &["my_msgs/msg/Thing"], &loader);
    assert_eq!(
        interfaces.diagnostics.len(),
        1,
        "{:#?}",
        interfaces.diagnostics
    );
    let diagnostic = &interfaces.diagnostics[0];
    assert_eq!(diagnostic.code, Code::UnknownType);
    assert_eq!(
        diagnostic.message,
        "no `.msg` file defines `geometry_msgs/msg/Pointt`"
    );
    assert_eq!(
        sources.display_path(diagnostic.file),
        "/msgs/my_msgs/msg/Thing.msg"
    );
    let span = diagnostic.primary_span();
    assert_eq!(
        &sources.text(diagnostic.file)[span.start..span.end],
        "geometry_msgs/Pointt[]"
    );
    assert_eq!(
        diagnostic.help.as_deref(),
        Some(
            "looked for\n  /msgs/geometry_msgs/msg/Pointt.msg\n  <shipped>/geometry_msgs/msg/Pointt.msg\n\
             did you mean `geometry_msgs/msg/Point`?"
        )
    );
    assert!(interfaces.description(&name("my_msgs/msg/Thing")).is_none());
}

#[test]
fn a_missing_wanted_type_is_reported_where_it_was_asked_for() {
    let (sources, interfaces) = load_all(
        &Search::new(),
        &["sensor_msgs/msg/Nope", "sensor_msgs/LaserScan"],
        &files(&[]),
    );
    let found: Vec<(Code, String, &str)> = interfaces
        .diagnostics
        .iter()
        .map(|d| {
            let span = d.primary_span();
            (
                d.code,
                sources.display_path(d.file),
                &sources.text(d.file)[span.start..span.end],
            )
        })
        .collect();
    assert_eq!(
        found,
        [
            (
                Code::UnknownType,
                "sensor_msgs/LaserScan.cool".into(),
                "sensor_msgs/LaserScan"
            ),
            (
                Code::UnknownType,
                "sensor_msgs/msg/Nope.cool".into(),
                "sensor_msgs/msg/Nope"
            ),
        ]
    );
    assert_eq!(
        interfaces.diagnostics[0].help.as_deref(),
        Some("write `sensor_msgs/msg/LaserScan`")
    );
}

#[test]
fn a_bare_header_outside_std_msgs_is_pointed_at_std_msgs() {
    let loader = files(&[("/m/my_msgs/msg/Stamped.msg", "Header header\n")]);
    let search = Search::new().with_dir("/m");
    let (_, interfaces) = load_all(&search, &["my_msgs/msg/Stamped"], &loader);
    let help = interfaces.diagnostics[0].help.clone().unwrap();
    assert!(
        help.ends_with("the standard header is `std_msgs/Header`"),
        "{help}"
    );
}

#[test]
fn an_unreadable_file_is_reported_with_its_error() {
    let loader = |path: &Path| -> io::Result<String> {
        if path == Path::new("/m/my_msgs/msg/Locked.msg") {
            Err(io::Error::new(io::ErrorKind::PermissionDenied, "denied"))
        } else {
            Err(io::ErrorKind::NotFound.into())
        }
    };
    let search = Search::new().with_dir("/m");
    let (_, interfaces) = load_all(&search, &["my_msgs/msg/Locked"], &loader);
    let diagnostic = &interfaces.diagnostics[0];
    assert_eq!(diagnostic.code, Code::ImportNotFound);
    assert_eq!(
        diagnostic.message,
        "cannot read /m/my_msgs/msg/Locked.msg: denied"
    );
}

#[test]
fn a_type_containing_itself_is_reported_at_the_closing_field() {
    let loader = files(&[
        ("/m/my_msgs/msg/A.msg", "int32 x\nB b\n"),
        ("/m/my_msgs/msg/B.msg", "A[] back\n"),
    ]);
    let search = Search::new().with_dir("/m");
    let (sources, interfaces) = load_all(&search, &["my_msgs/msg/A"], &loader);
    assert_eq!(
        interfaces.diagnostics.len(),
        1,
        "{:#?}",
        interfaces.diagnostics
    );
    let diagnostic = &interfaces.diagnostics[0];
    assert_eq!(diagnostic.code, Code::RecursivePacket);
    assert_eq!(
        diagnostic.message,
        "`my_msgs/msg/A` contains itself: my_msgs/msg/A -> my_msgs/msg/B -> my_msgs/msg/A"
    );
    let span = diagnostic.primary_span();
    assert_eq!(
        sources.display_path(diagnostic.file),
        "/m/my_msgs/msg/B.msg"
    );
    assert_eq!(&sources.text(diagnostic.file)[span.start..span.end], "A[]");
}

#[test]
fn no_description_of_a_type_whose_files_have_errors() {
    let loader = files(&[
        ("/m/my_msgs/msg/Top.msg", "Bad bad\n"),
        ("/m/my_msgs/msg/Bad.msg", "float x\n"),
        ("/m/my_msgs/msg/Fine.msg", "int32 x\n"),
    ]);
    let search = Search::new().with_dir("/m");
    let (_, interfaces) = load_all(&search, &["my_msgs/msg/Top", "my_msgs/msg/Fine"], &loader);
    assert!(interfaces.has_errors());
    assert!(interfaces.description(&name("my_msgs/msg/Top")).is_none());
    assert!(interfaces.description(&name("my_msgs/msg/Bad")).is_none());
    assert!(interfaces.description(&name("my_msgs/msg/Fine")).is_some());
}

#[test]
fn descriptions_list_referenced_types_sorted_and_describe_each_field_type() {
    let loader = files(&[(
        "/m/my_msgs/msg/All.msg",
        concat!(
            "uint8 K=1\n",
            "char c\nbyte b 7\nbool f\nstring<=4 s\nwstring w\nwstring<=2 ws\n",
            "float32[3] a\nint16[<=2] q\nuint64[] u\nstring<=4[<=3] t\n",
            "std_msgs/Header h\ngeometry_msgs/Point[] p\n",
        ),
    )]);
    let search = Search::new().with_dir("/m");
    let (_, interfaces) = load_all(&search, &["my_msgs/msg/All"], &loader);
    assert!(!interfaces.has_errors(), "{:#?}", interfaces.diagnostics);
    let description = interfaces.description(&name("my_msgs/msg/All")).unwrap();
    let fields: Vec<(&str, u8, u64, u64, &str)> = description
        .type_description
        .fields
        .iter()
        .map(|f| {
            let t = &f.field_type;
            (
                f.name.as_str(),
                t.type_id,
                t.capacity,
                t.string_capacity,
                t.nested_type_name.as_str(),
            )
        })
        .collect();
    assert_eq!(
        fields,
        [
            // rosidl turns a `.msg` char into uint8 (the hash does too).
            ("c", type_id::UINT8, 0, 0, ""),
            ("b", type_id::BYTE, 0, 0, ""),
            ("f", type_id::BOOLEAN, 0, 0, ""),
            ("s", type_id::BOUNDED_STRING, 0, 4, ""),
            ("w", type_id::WSTRING, 0, 0, ""),
            ("ws", type_id::BOUNDED_WSTRING, 0, 2, ""),
            ("a", 58, 3, 0, ""),
            ("q", 100, 2, 0, ""),
            ("u", 153, 0, 0, ""),
            ("t", 117, 3, 4, ""),
            ("h", type_id::NESTED_TYPE, 0, 0, "std_msgs/msg/Header"),
            ("p", 145, 0, 0, "geometry_msgs/msg/Point"),
        ]
    );
    let referenced: Vec<&str> = description
        .referenced_type_descriptions
        .iter()
        .map(|d| d.type_name.as_str())
        .collect();
    assert_eq!(
        referenced,
        [
            "builtin_interfaces/msg/Time",
            "geometry_msgs/msg/Point",
            "std_msgs/msg/Header"
        ]
    );
}

#[test]
fn an_empty_message_is_described_with_rosidls_placeholder_field() {
    let loader = files(&[("/m/my_msgs/msg/Empty.msg", "# nothing\nuint8 ONLY=1\n")]);
    let search = Search::new().with_dir("/m");
    let (_, interfaces) = load_all(&search, &["my_msgs/msg/Empty"], &loader);
    let description = interfaces.description(&name("my_msgs/msg/Empty")).unwrap();
    let json = coolc::ros::hash::hashed_json(&description);
    assert_eq!(
        json,
        r#"{"type_description": {"type_name": "my_msgs/msg/Empty", "fields": [{"name": "structure_needs_at_least_one_member", "type": {"type_id": 3, "capacity": 0, "string_capacity": 0, "nested_type_name": ""}}]}, "referenced_type_descriptions": []}"#
    );
}

#[test]
fn constants_and_defaults_do_not_change_the_hash() {
    let loader = files(&[
        ("/a/my_msgs/msg/T.msg", "int32 x\nfloat64 y\n"),
        (
            "/b/my_msgs/msg/T.msg",
            "uint8 K=3\nint32 x 5 # a default\nfloat64 y 2.5\n",
        ),
        ("/c/my_msgs/msg/T.msg", "int32 x\nfloat32 y\n"),
    ]);
    let hash = |dir: &str| {
        let (_, interfaces) = load_all(&Search::new().with_dir(dir), &["my_msgs/msg/T"], &loader);
        interfaces.hash(&name("my_msgs/msg/T")).unwrap()
    };
    assert_eq!(hash("/a"), hash("/b"));
    assert_ne!(hash("/a"), hash("/c"));
}

/// Run by `search_from_env_reads_ament_prefix_path` in a child process with
/// `AMENT_PREFIX_PATH` set (a test cannot set the environment of its own process).
#[test]
#[ignore = "run by search_from_env_reads_ament_prefix_path"]
fn search_from_env_child() {
    let search = Search::from_env([PathBuf::from("/given")]);
    let candidates = search.candidates(&name("std_msgs/msg/Header"));
    let expected: Vec<PathBuf> = [
        "/given/std_msgs/msg/Header.msg",
        "/opt/one/share/std_msgs/msg/Header.msg",
        "/opt/two/share/std_msgs/msg/Header.msg",
        "<shipped>/std_msgs/msg/Header.msg",
    ]
    .iter()
    .map(PathBuf::from)
    .collect();
    assert_eq!(candidates, expected);
}

#[test]
fn search_from_env_reads_ament_prefix_path() {
    let value = std::env::join_paths(["/opt/one", "/opt/two"]).unwrap();
    // The child's name as the test binary lists it: its module path without the crate.
    let child = match module_path!().split_once("::") {
        Some((_, module)) => format!("{module}::search_from_env_child"),
        None => "search_from_env_child".to_owned(),
    };
    let output = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--ignored", "--exact", &child])
        .env("AMENT_PREFIX_PATH", value)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success() && stdout.contains("1 passed"),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// The `rust` block of `docs/ros2.md`, "The library: `coolc::ros`", is the doc
/// example of `coolc::ros`, which runs as a doc test: the two must stay the same text.
#[test]
fn the_documented_example_is_the_module_doc_test() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(manifest.join("../docs/ros2.md")).unwrap();
    let section = doc
        .find("\n## The library: `coolc::ros`\n")
        .expect("docs/ros2.md documents the library");
    let start = section
        + doc[section..]
            .find("```rust\n")
            .expect("the library's section has a rust block")
        + 8;
    let documented = &doc[start..start + doc[start..].find("```\n").unwrap()];
    let module = std::fs::read_to_string(manifest.join("src/ros/mod.rs")).unwrap();
    let lines: Vec<&str> = module
        .lines()
        .map_while(|line| line.strip_prefix("//!"))
        .map(|line| line.strip_prefix(' ').unwrap_or(line))
        .skip_while(|line| *line != "```")
        .skip(1)
        .take_while(|line| *line != "```")
        .collect();
    assert_eq!(documented, format!("{}\n", lines.join("\n")));
}

#[test]
fn a_float32_value_fits_up_to_the_largest_f32() {
    let message = clean("float32 a 3.4028235e38\nfloat32 b -inf\nfloat64 c 1e39\nfloat32 D=nan\n");
    let defaults: Vec<Option<f64>> = message
        .fields
        .iter()
        .map(|f| match &f.default {
            Some((Value::Float(value), _)) => Some(*value),
            _ => None,
        })
        .collect();
    assert_eq!(
        defaults,
        [Some(3.4028235e38), Some(f64::NEG_INFINITY), Some(1e39)]
    );
    assert!(matches!(message.constants[0].value, Value::Float(v) if v.is_nan()));
}
