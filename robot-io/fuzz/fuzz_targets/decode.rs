//! Arbitrary bytes into every RTDE decoder: no panic, no unbounded allocation (libFuzzer's
//! `-rss_limit_mb` and `-malloc_limit_mb` catch the latter).
#![no_main]

use libfuzzer_sys::fuzz_target;
use robot_io::codec::{ClientPackage, ControllerPackage, FieldType, Recipe, Value, split_package};

fuzz_target!(|bytes: &[u8]| {
    let _ = ClientPackage::decode(bytes);
    let _ = ControllerPackage::decode(bytes);
    let _ = split_package(bytes);
    // A recipe as a controller's setup reply would build it, then a data package against it.
    if let Ok(recipe) = Recipe::new(
        1,
        &["timestamp", "actual_q", "runtime_state", "flag"],
        &[
            FieldType::Double,
            FieldType::Vector6d,
            FieldType::Uint32,
            FieldType::Bool,
        ],
    ) {
        let mut out = [Value::Bool(false); 4];
        if let Ok(ControllerPackage::Data(d)) = ControllerPackage::decode(bytes) {
            if let Ok(payload) = recipe.check(&d) {
                let _ = recipe.decode_into(payload, &mut out);
            }
        }
        let _ = recipe.decode_into(bytes, &mut out);
    }
    // Setup replies with arbitrary type strings.
    if let Some((&id, rest)) = bytes.split_first() {
        if let Ok(types) = std::str::from_utf8(rest) {
            let _ = Recipe::from_setup_reply(id, &["a", "b", "c"], types);
        }
    }
    for ty in FieldType::ALL {
        let _ = Value::decode(ty, bytes, bytes.len() / 2);
    }
});
