//! Runs the crate's components for two seconds and prints what their monitoring
//! ports show, then the shutdown report.
//!
//! `coolc` wrote this file when it created the crate and never changes it: it is
//! yours. It starts each component that no compound of the crate instantiated at
//! that time; a component described later is not added here by itself.

use std::time::Duration;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut system = coolbot::System::new();
    let handles: [coolbot::Handle; {{ roots.len() }}] = [
{%- for root in roots %}
        system
            .add({{ root }})
            .map_err(|e| format!("cannot add a component: {e}"))?,
{%- endfor %}
    ];
    // Start the components' threads and command them to `running`.
    system.run_all().map_err(|e| format!("cannot start: {e}"))?;
    std::thread::sleep(Duration::from_secs(2));
    for handle in &handles {
        println!("{:#?}", handle.snapshot());
    }
    let report = system.shutdown();
    println!("{report:?}");
    Ok(())
}
