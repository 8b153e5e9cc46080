//! `Value` conversions, `Time`, `Fault`, and a generated spec that passes the checks
//! `System::add` makes (the specs they refuse, which coolc never generates, are in
//! `runtime/tests/invalid_specs.rs`).

use std::time::Duration;

use coolbot::port::FifoIn;
use coolbot::{Fault, System, Time, Value};
use coolbot_runtime_tests::support::{Script, Scripted};
use coolbot_runtime_tests::worker;

#[test]
fn primitives_round_trip_through_value() {
    assert_eq!(i64::try_from(&Value::from(-5i32)), Ok(-5));
    assert_eq!(u8::try_from(&Value::from(200u64)), Ok(200));
    assert_eq!(
        u8::try_from(&Value::from(300u64)).unwrap_err().to_string(),
        "expected u8, got uint"
    );
    assert_eq!(i8::try_from(&Value::from(-1i64)), Ok(-1));
    assert_eq!(
        u32::try_from(&Value::Int(-1)).unwrap_err().to_string(),
        "expected u32, got int"
    );
    assert_eq!(f64::try_from(&Value::from(1.5f32)), Ok(1.5));
    assert_eq!(f64::try_from(&Value::Int(2)), Ok(2.0));
    assert_eq!(bool::try_from(&Value::from(true)), Ok(true));
    assert_eq!(String::try_from(&Value::from("hi")), Ok("hi".to_owned()));
    assert_eq!(
        Duration::try_from(&Value::from(Duration::from_millis(3))),
        Ok(Duration::from_millis(3))
    );
    assert_eq!(
        Time::try_from(&Value::from(Time::from_nanos(7))),
        Ok(Time(7))
    );
    assert_eq!(Value::from(None::<u8>), Value::Unit);
    assert_eq!(
        Value::from(vec![1u8, 2]),
        Value::List(vec![Value::UInt(1), Value::UInt(2)])
    );
    assert_eq!(i64::try_from(&Value::Json(serde_json::json!(12))), Ok(12));
    assert!(bool::try_from(&Value::Int(1)).is_err());
}

#[test]
fn records_and_json_convert_to_user_types() {
    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Pose {
        x: f64,
        name: String,
    }
    let record = Value::Record(vec![
        ("x".to_owned(), Value::Float(1.0)),
        ("name".to_owned(), Value::from("a")),
    ]);
    assert_eq!(
        record.to_serde::<Pose>().expect("a Pose"),
        Pose {
            x: 1.0,
            name: "a".to_owned()
        }
    );
    assert_eq!(record.field("x"), Some(Value::Float(1.0)));
    assert_eq!(record.field("y"), None);
    let json = Value::from_serde(&Pose {
        x: 2.0,
        name: "b".to_owned(),
    })
    .expect("serialize");
    assert_eq!(
        json.field("name"),
        Some(Value::Json(serde_json::json!("b")))
    );
    let error = Value::Str("x".to_owned()).to_serde::<Pose>().unwrap_err();
    assert!(
        matches!(error, coolbot::ConvertError::Deserialize(_)),
        "{error:?}"
    );
    assert_eq!(
        coolbot::Chain(&error).to_string(),
        "the value does not match its type: invalid type: string \"x\", expected struct Pose"
    );
    assert_eq!(Value::from("q").to_string(), r#""q""#);
}

#[test]
fn time_is_nanoseconds_since_the_epoch() {
    let now = Time::now();
    assert!(now.as_nanos() > 1_600_000_000_000_000_000, "after 2020");
    assert_eq!(
        Time(5_000).duration_since(Time(2_000)),
        Duration::from_nanos(3_000)
    );
    assert_eq!(Time(1).duration_since(Time(2)), Duration::ZERO);
    assert_eq!(serde_json::to_string(&Time(42)).unwrap(), "42");
}

#[test]
fn faults_convert_from_errors() {
    fn parse(text: &str) -> Result<u32, Fault> {
        Ok(text.parse::<u32>()?)
    }
    let fault = parse("x").unwrap_err();
    assert_eq!(fault.exception_index(), None);
    assert_eq!(fault.text(), "invalid digit found in string");
    let declared = Fault::exception(2, "lost");
    assert_eq!(declared.exception_index(), Some(2));
    assert_eq!(declared.to_string(), "exception #2: lost");
}

#[test]
fn the_worker_spec_is_valid() {
    assert_eq!(worker::SPEC.validate(), Ok(()));
    let component = worker::component("w", Scripted::new(&Script::new()));
    assert!(System::new().add(component).is_ok());
    assert_eq!(
        worker::SPEC.state_index("busy"),
        Some(worker::UserState::Busy.index())
    );
    assert_eq!(worker::SPEC.input_index("feed"), Some(2));
    assert_eq!(worker::SPEC.output_index("out"), Some(0));
}

#[test]
fn handles_and_ports_can_cross_threads() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<coolbot::Handle>();
    send_sync::<coolbot::port::TickIn>();
    send_sync::<coolbot::port::TickOut>();
    send_sync::<FifoIn<String>>();
    send_sync::<coolbot::port::UfifoIn<String>>();
    send_sync::<coolbot::port::LastIn<String>>();
    send_sync::<coolbot::port::PosterIn<String>>();
    send_sync::<coolbot::port::DataOut<String>>();
    send_sync::<coolbot::port::PosterOut<String>>();
    fn send<T: Send>() {}
    send::<System>();
    send::<coolbot::Component>();
}
