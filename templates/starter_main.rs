//! Runs one `{{ c.type_name }}` for a couple of seconds and prints what its monitoring
//! port shows.

use std::time::Duration;


fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut system = coolbot::System::new();
    let behavior = ::{{ krate.lib_name }}::{{ c.module }}::{{ c.user_struct }}::default();
    let component = ::{{ krate.lib_name }}::generated::{{ c.module }}::component("{{ c.module }}", behavior);
    let handle = system.add(component).map_err(|e| format!("cannot add the component: {e}"))?;
    // Start the component's thread and command it to `running`.
    system.run_all().map_err(|e| format!("cannot start: {e}"))?;
    std::thread::sleep(Duration::from_secs(2));
    println!("{:#?}", handle.snapshot());
    let report = system.shutdown();
    println!("{report:?}");
    Ok(())
}
