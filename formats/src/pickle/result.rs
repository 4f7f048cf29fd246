//! The finished pickle as a [`Value`]: shared payloads moved out (or copied when still shared), and dicts built
//! with Python's key rules (`1 == 1.0 == True`, the last value of a repeated key at the first key's place,
//! unhashable keys refused).

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::rc::Rc;

use super::Value;
use super::item::{Item, Step};

/// A dict key as Python compares it: `1 == 1.0 == True`; `None` for keys equal to nothing else (NaN).
#[derive(Debug, PartialEq, Eq, Hash)]
enum Key {
    None,
    Int(i64),
    Float(u64),
    Str(String),
    Bytes(Vec<u8>),
    Tuple(Vec<Key>),
}

fn key_of(v: &Value) -> Step<Option<Key>> {
    Ok(Some(match v {
        Value::None => Key::None,
        Value::Bool(b) => Key::Int(i64::from(*b)),
        Value::Int(i) => Key::Int(*i),
        Value::Float(f) if f.is_nan() => return Ok(None),
        // Integral floats in i64 range equal the int (-0.0 == 0); 2^63 itself is out of range.
        Value::Float(f) if f.fract() == 0.0 && *f >= -(2f64.powi(63)) && *f < 2f64.powi(63) => Key::Int(*f as i64),
        Value::Float(f) => Key::Float(f.to_bits()),
        Value::Str(s) => Key::Str(s.clone()),
        Value::Bytes(b) => Key::Bytes(b.clone()),
        Value::Tuple(items) => {
            let mut keys = Vec::with_capacity(items.len());
            for item in items {
                match key_of(item)? {
                    Some(k) => keys.push(k),
                    None => return Ok(None),
                }
            }
            Key::Tuple(keys)
        }
        other => {
            return Err(format!(
                "dict key is a {} (unhashable: Python refuses this pickle too)",
                other.kind()
            ));
        }
    }))
}

/// The finished item as a [`Value`]; dict keys as Python's dict keeps them (last value wins).
pub(super) fn value(item: Item) -> Step<Value> {
    Ok(match item {
        Item::None => Value::None,
        Item::Bool(b) => Value::Bool(b),
        Item::Int(i) => Value::Int(i),
        Item::Float(f) => Value::Float(f),
        Item::Str(s) => Value::Str(unshare(s)),
        Item::Bytes(b) => Value::Bytes(unshare(b)),
        Item::List(v) => Value::List(v.into_iter().map(value).collect::<Step<_>>()?),
        Item::Tuple(v) => Value::Tuple(v.into_iter().map(value).collect::<Step<_>>()?),
        Item::Dict(kv) => {
            let mut out: Vec<(Value, Value)> = Vec::with_capacity(kv.len());
            let mut seen: HashMap<Key, usize> = HashMap::with_capacity(kv.len());
            for (k, v) in kv {
                let (k, v) = (value(k)?, value(v)?);
                match key_of(&k)? {
                    Some(key) => match seen.entry(key) {
                        Entry::Occupied(e) => out[*e.get()].1 = v,
                        Entry::Vacant(e) => {
                            e.insert(out.len());
                            out.push((k, v));
                        }
                    },
                    None => out.push((k, v)),
                }
            }
            Value::Dict(out)
        }
        Item::Array(a) => Value::NdArray(unshare(a)),
        other => return Err(format!("a {} object is left in the data", other.kind())),
    })
}

/// A payload for the result: moved out at its last reference, else copied (paid for before the conversion starts).
fn unshare<T: Clone>(rc: Rc<T>) -> T {
    Rc::try_unwrap(rc).unwrap_or_else(|rc| (*rc).clone())
}
