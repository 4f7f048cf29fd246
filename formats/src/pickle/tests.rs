//! Tests of the pickle reader and writer: opcodes, hostile input (globals, bombs, frames), Python's dict rules.

use super::numpy::{f16_to_f64, fortran_to_c};
use super::*;
use crate::error::DataError;

fn err(bytes: &[u8]) -> DataError {
    loads(bytes, "t.bin").unwrap_err()
}

#[test]
fn scalars_and_containers() {
    // protocol 2: {'a': [1, -2, 3.5, None, True], 'b': (b'xy',)}
    let mut p = vec![0x80, 2, b'}', b'(', b'X', 1, 0, 0, 0, b'a', b']', b'('];
    p.extend([b'K', 1, b'J', 0xfe, 0xff, 0xff, 0xff, b'G']);
    p.extend(3.5f64.to_be_bytes());
    p.extend([b'N', 0x88, b'e', 0x8c, 1, b'b', b'C', 2, b'x', b'y', 0x85, b'u', b'.']);
    let v = loads(&p, "t.bin").unwrap();
    assert_eq!(
        v.get("a"),
        Some(&Value::List(vec![
            Value::Int(1),
            Value::Int(-2),
            Value::Float(3.5),
            Value::None,
            Value::Bool(true)
        ]))
    );
    assert_eq!(v.get("b"), Some(&Value::Tuple(vec![Value::Bytes(b"xy".to_vec())])));
}

#[test]
fn long1_is_twos_complement() {
    let v = loads(&[0x80, 2, 0x8a, 2, 0x00, 0xff, b'.'], "t").unwrap();
    assert_eq!(v, Value::Int(-256));
    let v = loads(&[0x80, 2, 0x8a, 2, 0x00, 0x01, b'.'], "t").unwrap();
    assert_eq!(v, Value::Int(256));
}

#[test]
fn hostile_global_is_refused_by_name() {
    let e = err(b"\x80\x02cos\nsystem\nX\x04\x00\x00\x00echo\x85R.");
    assert_eq!(e.field, "pickle");
    assert!(e.reason.contains("`os.system`") && e.reason.contains("byte 2"), "{e}");
    let e = err(b"\x80\x04\x8c\x08builtins\x8c\x04eval\x93.");
    assert!(e.reason.contains("`builtins.eval`"), "{e}");
}

#[test]
fn truncated_unknown_and_underflow() {
    assert!(err(&[0x80, 2, b'X', 9, 0, 0, 0, b'a']).reason.contains("truncated"));
    assert!(err(&[0x80, 2, b'N']).reason.contains("before STOP"));
    assert!(err(&[0x80, 2, 0xff]).reason.contains("opcode 0xff"));
    assert!(err(&[0x80, 2, b't', b'.']).reason.contains("without MARK"));
    assert!(err(&[0x80, 2, b'(', b'.']).reason.contains("underflow"));
    assert!(err(&[0x80, 2, b'h', 3]).reason.contains("memo key 3"));
}

#[test]
fn bombs_and_deep_nesting_are_errors() {
    let mut bomb = vec![0x80, 4, b'N'];
    for _ in 0..40 {
        bomb.extend([b'2', 0x86]); // DUP, TUPLE2: doubles the size each time
    }
    bomb.push(b'.');
    assert!(err(&bomb).reason.contains("pickle bomb"), "{}", err(&bomb));
    let mut deep = vec![0x80, 4];
    deep.extend([b']'; 300]);
    deep.extend([b'a'; 299]);
    deep.push(b'.');
    assert!(err(&deep).reason.contains("deeper than 256"), "{}", err(&deep));
    // 200 levels are fine.
    let mut ok = vec![0x80, 4];
    ok.extend([b']'; 200]);
    ok.extend([b'a'; 199]);
    ok.push(b'.');
    assert!(loads(&ok, "t").is_ok());
}

#[test]
fn half_floats_and_fortran_order() {
    assert_eq!(f16_to_f64(0x3c00), 1.0);
    assert_eq!(f16_to_f64(0xc000), -2.0);
    assert_eq!(f16_to_f64(0x0001), 2f64.powi(-24));
    // column-major [[0,1,2],[3,4,5]] stored as 0,3,1,4,2,5
    assert_eq!(fortran_to_c(&[0, 3, 1, 4, 2, 5], &[2, 3]), vec![0, 1, 2, 3, 4, 5]);
}

#[test]
fn writer_round_trips_through_reader() {
    let v = Value::Dict(vec![
        (
            Value::Str("vertices".into()),
            Value::NdArray(NdArray {
                shape: vec![2, 1, 3],
                dtype: DType::F4,
                data: ArrayData::Float(vec![0.5, -1.0, 2.0, 3.25, 1e-3f32 as f64, 7.0]),
            }),
        ),
        (
            Value::Str("faces".into()),
            Value::NdArray(NdArray {
                shape: vec![1, 3],
                dtype: DType::I8,
                data: ArrayData::Int(vec![0, 1, -2]),
            }),
        ),
        (Value::Str("caption".into()), Value::Str("a cat ".repeat(60))),
        (
            Value::Str("n".into()),
            Value::List(vec![Value::Int(-70000), Value::Int(1 << 40), Value::Bool(false)]),
        ),
    ]);
    let bytes = dumps(&v).unwrap();
    assert_eq!(loads(&bytes, "t").unwrap(), v);
}

/// `N`, then `doublings` × (DUP, TUPLE2): a tuple tree of 2^(doublings+1) − 1 values.
fn doubled(doublings: usize) -> Vec<u8> {
    let mut p = vec![0x80, 4, b'N'];
    for _ in 0..doublings {
        p.extend([b'2', 0x86]);
    }
    p
}

#[test]
fn memo_stores_and_fetches_are_charged() {
    // The 86-byte file of the fuzzing report: 21 doublings, then 40 MEMOIZE (each used to copy the whole tree).
    let mut bomb = doubled(21);
    bomb.extend([0x94; 40]);
    bomb.push(b'.');
    assert_eq!(bomb.len(), 86);
    assert!(err(&bomb).reason.contains("pickle bomb"), "{}", err(&bomb));
    // A tree of 2^16 values stored under 40 keys by every put opcode, then fetched: the fetches hit the limit.
    for put in [vec![0x94], vec![b'q', 7], vec![b'r', 7, 0, 0, 0], b"p7\n".to_vec()] {
        let mut p = doubled(15);
        let tree_end = p.len();
        p.extend(&put);
        let key = if put == [0x94] { 0 } else { 7 }; // MEMOIZE stores under the memo size
        for _ in 0..40 {
            p.extend([b'h', key, b'0']); // BINGET, POP
        }
        p.push(b'.');
        let e = err(&p);
        assert!(e.reason.contains("pickle bomb"), "{put:?}: {e}");
        let at: usize = e.reason["byte ".len()..].split(':').next().unwrap().parse().unwrap();
        assert!(at > tree_end, "{put:?}: fails at byte {at}, inside the tree: {e}");
    }
    // Storing is free: a large tree memoised under many keys is fine as long as nothing copies it.
    let mut p = doubled(15);
    p.extend([0x94; 200]);
    p.push(b'.');
    assert!(loads(&p, "t").is_ok());
}

#[test]
fn shared_payloads_are_charged_when_copied_out() {
    // One 64 KiB bytes object referenced 5000 times: 320 MB of copies, refused before any is made.
    let mut p = vec![0x80, 4, b'(', 0x8e];
    p.extend((1u64 << 16).to_le_bytes());
    p.extend(vec![0xab; 1 << 16]);
    p.extend([b'2'; 4999]);
    p.extend([b't', b'.']);
    let e = err(&p);
    assert!(
        e.reason.contains("would copy") && e.reason.contains("pickle bomb"),
        "{e}"
    );
    // A few references are fine and give equal copies.
    let mut p = vec![
        0x80, 4, b'(', b'C', 3, b'a', b'b', b'c', 0x94, b'h', 0, b'h', 0, b't', b'.',
    ];
    let v = loads(&p, "t").unwrap();
    assert_eq!(v, Value::Tuple(vec![Value::Bytes(b"abc".to_vec()); 3]));
    p[2] = b'N'; // no MARK: TUPLE without MARK
    assert!(err(&p).reason.contains("without MARK"));
}

#[test]
fn memo_reference_to_an_object_on_the_stack_sees_its_state() {
    // What Python writes for `x = [1]; pickle.dumps((x, x), 4)` and `pickle.dumps({'a': x, 'b': x}, 2)`.
    let tuple = [
        0x80, 4, 0x95, 10, 0, 0, 0, 0, 0, 0, 0, b']', 0x94, b'K', 1, b'a', b'h', 0, 0x86, 0x94, b'.',
    ];
    let one = Value::List(vec![Value::Int(1)]);
    assert_eq!(
        loads(&tuple, "t").unwrap(),
        Value::Tuple(vec![one.clone(), one.clone()])
    );
    let mut dict = vec![
        0x80, 2, b'}', b'q', 0, b'(', b'X', 1, 0, 0, 0, b'a', b'q', 1, b']', b'q', 2,
    ];
    dict.extend([b'K', 1, b'a', b'X', 1, 0, 0, 0, b'b', b'q', 3, b'h', 2, b'u', b'.']);
    let v = loads(&dict, "t").unwrap();
    assert_eq!((v.get("a"), v.get("b")), (Some(&one), Some(&one)));
}

#[test]
fn frames_must_hold_what_they_claim() {
    // FRAME 10 around `] MEMOIZE K 1 a h 0 TUPLE2 MEMOIZE .` (10 bytes after the frame header): fine.
    let good = [
        0x80, 4, 0x95, 10, 0, 0, 0, 0, 0, 0, 0, b']', 0x94, b'K', 1, b'a', b'h', 0, 0x86, 0x94, b'.',
    ];
    assert!(loads(&good, "t").is_ok());
    // The frame claims more bytes than remain.
    let mut long = good;
    long[3] = 11;
    assert!(
        err(&long).reason.contains("FRAME claims 11 bytes, 10 left"),
        "{}",
        err(&long)
    );
    let mut huge = good;
    huge[3..11].copy_from_slice(&u64::MAX.to_le_bytes());
    assert!(err(&huge).reason.contains("FRAME claims"), "{}", err(&huge));
    // A frame that ends inside an opcode (BININT1's argument).
    let mut short = good;
    short[3] = 3;
    assert!(err(&short).reason.contains("cross a frame end"), "{}", err(&short));
    // A frame that starts inside another.
    let nested = [
        0x80, 4, 0x95, 11, 0, 0, 0, 0, 0, 0, 0, 0x95, 1, 0, 0, 0, 0, 0, 0, 0, b'N', b'.',
    ];
    assert!(err(&nested).reason.contains("before the end"), "{}", err(&nested));
    // Consecutive frames are fine, and so is data after the last frame.
    let two = [
        0x80, 4, 0x95, 1, 0, 0, 0, 0, 0, 0, 0, b'N', 0x95, 2, 0, 0, 0, 0, 0, 0, 0, b'N', 0x86, b'.',
    ];
    assert_eq!(loads(&two, "t").unwrap(), Value::Tuple(vec![Value::None, Value::None]));
}

#[test]
fn duplicate_dict_keys_keep_the_last_value_at_the_first_position() {
    // {'a': 1, 'b': 2, 'a': 3} by SETITEMS, then {1: 'x', True: 'y', 1.0: 'z', 2: 'w'} by DICT.
    let mut p = vec![0x80, 2, b'(', b'}', b'('];
    for (k, v) in [(b'a', 1), (b'b', 2), (b'a', 3)] {
        p.extend([0x8c, 1, k, b'K', v]);
    }
    p.extend([b'u', b'(', b'K', 1, 0x8c, 1, b'x', 0x88, 0x8c, 1, b'y', b'G']);
    p.extend(1.0f64.to_be_bytes());
    p.extend([0x8c, 1, b'z', b'K', 2, 0x8c, 1, b'w', b'd', b'l', b'.']);
    let v = loads(&p, "t").unwrap();
    let s = |t: &str| Value::Str(t.into());
    let Value::List(dicts) = v else { panic!("{v:?}") };
    assert_eq!(
        dicts[0],
        Value::Dict(vec![(s("a"), Value::Int(3)), (s("b"), Value::Int(2))])
    );
    assert_eq!(
        dicts[1],
        Value::Dict(vec![(Value::Int(1), s("z")), (Value::Int(2), s("w"))])
    );
    // Unhashable keys are refused, as Python refuses them; NaN keys never collide.
    let e = err(&[0x80, 2, b'}', b']', b'N', b's', b'.']);
    assert!(e.reason.contains("unhashable"), "{e}");
    let mut nan = vec![0x80, 2, b'}', b'(', b'G'];
    nan.extend(f64::NAN.to_be_bytes());
    nan.extend([b'N', b'G']);
    nan.extend(f64::NAN.to_be_bytes());
    nan.extend([b'N', b'u', b'.']);
    let Value::Dict(items) = loads(&nan, "t").unwrap() else {
        panic!()
    };
    assert_eq!(items.len(), 2);
}
