//! The emulator's sim mode serves every RTDE guide output field, speaks protocol version 1
//! as well as 2, and streams several output recipes on one connection (issue 11). Raw
//! packages over loopback; no assertion depends on wall-clock speed.

mod common;

use common::{Raw, TEST_TIMEOUT};
use robot_io::codec::{ClientPackage, FieldType, Value, known_field_type};
use robot_io::emulator::EmulatorConfig;
use robot_io::emulator::sim_fields::{AMBIENT_C, BUS_V, SIM_OUTPUT_FIELDS};

async fn sim_emulator() -> robot_io::emulator::Emulator {
    common::sim_emulator(EmulatorConfig::ephemeral()).await
}

fn decode_all(types: &[FieldType], payload: &[u8]) -> Vec<Value> {
    let mut at = 0;
    let out = types
        .iter()
        .map(|t| {
            let v = Value::decode(*t, payload, at).unwrap();
            at += t.size();
            v
        })
        .collect();
    assert_eq!(at, payload.len(), "payload size");
    out
}

/// Every field of the table is accepted with its guide type (the codec knows each with the
/// same type), in one recipe, and streams values of that size; and the derived values are
/// physically consistent: a RUNNING arm at 48 V, temperatures at or above ambient, the
/// accelerometer reading 1 g, currents of the moment's sign.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_rtde_guide_output_field_is_served_with_its_type() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let emu = sim_emulator().await;
        let mut c = Raw::connect(&emu).await;
        assert!(c.version(2).await);
        // The codec knows every field the sim backend serves, with the same type, so a trace
        // that recorded one of them replays it instead of answering NOT_FOUND.
        for (name, ty) in SIM_OUTPUT_FIELDS {
            assert_eq!(
                known_field_type(name),
                Some(ty),
                "{name}: the codec's type differs from the sim backend's"
            );
        }
        // The guide's 2048-byte bound on a name list: two recipes.
        let (a, b) = SIM_OUTPUT_FIELDS.split_at(35);
        let mut all = Vec::new();
        for half in [a, b] {
            let names: Vec<&str> = half.iter().map(|(n, _)| *n).collect();
            let mut payload = 125.0f64.to_be_bytes().to_vec();
            payload.extend_from_slice(names.join(",").as_bytes());
            c.send_raw(b'O', &payload).await;
            let reply = c.recv_kind(b'O').await;
            let types = std::str::from_utf8(&reply[1..]).unwrap();
            let want: Vec<&str> = half.iter().map(|(_, t)| t.as_str()).collect();
            assert_eq!(types, want.join(","));
            assert_ne!(reply[0], 0);
            all.push((reply[0], half));
        }
        c.send(ClientPackage::Start).await;
        assert_eq!(c.recv_kind(b'S').await, [1]);
        let mut seen = std::collections::HashMap::new();
        while seen.len() < 2 {
            let p = c.recv_kind(b'U').await;
            let (id, half) = all.iter().find(|(id, _)| *id == p[0]).expect("recipe id");
            let types: Vec<FieldType> = half.iter().map(|(_, t)| *t).collect();
            let values = decode_all(&types, &p[1..]);
            let named: Vec<(&str, Value)> = half.iter().map(|(n, _)| *n).zip(values).collect();
            seen.insert(*id, named);
        }
        let get = |name: &str| {
            seen.values()
                .flatten()
                .find(|(n, _)| *n == name)
                .map(|(_, v)| *v)
                .unwrap()
        };
        assert_eq!(get("robot_mode"), Value::Int32(7));
        assert_eq!(get("joint_mode"), Value::Vector6Int32([253; 6]));
        assert_eq!(get("actual_robot_voltage"), Value::Double(BUS_V));
        let Value::Vector6d(temps) = get("joint_temperatures") else {
            panic!()
        };
        assert!(
            temps.iter().all(|t| *t >= AMBIENT_C && *t < 80.0),
            "{temps:?}"
        );
        let Value::Vector3d(acc) = get("actual_tool_accelerometer") else {
            panic!()
        };
        let g = acc.iter().map(|a| a * a).sum::<f64>().sqrt();
        assert!((g - 9.81).abs() < 1e-6, "accelerometer {acc:?}");
        let (Value::Vector6d(i), Value::Vector6d(m)) =
            (get("target_current"), get("target_moment"))
        else {
            panic!()
        };
        assert!(i.iter().zip(m).all(|(i, m)| i * m >= 0.0));
        let Value::Double(robot_current) = get("actual_robot_current") else {
            panic!()
        };
        assert!(robot_current > 0.0);
    })
    .await
    .expect("test timed out");
}

/// Protocol version 1 as UR's guide describes it: the output setup carries no frequency
/// (125 Hz) and its reply no recipe id; data packages carry no recipe id either way; an
/// input package without id writes the input recipe set up.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn protocol_version_1_has_no_frequency_and_no_recipe_ids() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let emu = sim_emulator().await;
        let mut c = Raw::connect(&emu).await;
        assert!(!c.version(3).await, "version 3 is refused");
        assert!(c.version(1).await);
        c.send_raw(b'O', b"timestamp,input_int_register_24").await;
        assert_eq!(c.recv_kind(b'O').await, b"DOUBLE,INT32");
        c.send_raw(b'I', b"input_int_register_24").await;
        assert_eq!(c.recv_kind(b'I').await, b"\x01INT32");
        c.send_raw(b'U', &42i32.to_be_bytes()).await;
        c.send(ClientPackage::Start).await;
        assert_eq!(c.recv_kind(b'S').await, [1]);
        let mut stamps = Vec::new();
        loop {
            let (k, p) = c.recv_frame().await;
            if k == b'M' {
                // Version 1 text: level, then the message.
                assert!(p[0] <= 3 && p.len() > 1);
                continue;
            }
            assert_eq!(k, b'U');
            assert_eq!(p.len(), 8 + 4, "no recipe id in a version 1 data package");
            let v = decode_all(&[FieldType::Double, FieldType::Int32], &p);
            let Value::Double(t) = v[0] else { panic!() };
            stamps.push(t);
            if v[1] == Value::Int32(42) && stamps.len() >= 3 {
                break;
            }
        }
        for w in stamps.windows(2) {
            let cycles = (w[1] - w[0]) / 0.002;
            assert!(
                (cycles - 4.0).abs() < 1e-6,
                "125 Hz is every 4th cycle: {stamps:?}"
            );
        }
    })
    .await
    .expect("test timed out");
}

/// Several output recipes on one protocol-2 connection each stream at their own
/// frequency with their own id.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn several_output_recipes_stream_at_their_own_frequencies() {
    tokio::time::timeout(TEST_TIMEOUT, async {
        let emu = sim_emulator().await;
        let mut c = Raw::connect(&emu).await;
        assert!(c.version(2).await);
        for (freq, names) in [(500.0, "timestamp"), (100.0, "timestamp,robot_mode")] {
            c.send(ClientPackage::SetupOutputs {
                frequency_hz: freq,
                names,
            })
            .await;
            let r = c.recv_kind(b'O').await;
            assert_ne!(r[0], 0);
        }
        c.send(ClientPackage::Start).await;
        assert_eq!(c.recv_kind(b'S').await, [1]);
        let mut by_id: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
        while by_id.iter().any(|s| s.len() < 4) {
            let p = c.recv_kind(b'U').await;
            let id = usize::from(p[0]);
            assert!(id == 1 || id == 2, "recipe {id}");
            let want = if id == 1 { 8 } else { 12 };
            assert_eq!(p.len() - 1, want);
            let Value::Double(t) = Value::decode(FieldType::Double, &p[1..], 0).unwrap() else {
                panic!()
            };
            by_id[id - 1].push(t);
        }
        for (stamps, every) in by_id.iter().zip([1.0, 5.0]) {
            for w in stamps.windows(2) {
                let k = (w[1] - w[0]) / (0.002 * every);
                assert!(
                    (k - k.round()).abs() < 1e-6 && k >= 1.0 - 1e-9,
                    "{stamps:?}"
                );
            }
        }
    })
    .await
    .expect("test timed out");
}
