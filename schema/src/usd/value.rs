//! Conversions from composed `sdf::Value`s to the plain types the core uses.
//! Accept every precision USD allows for a role (point3f/point3d/point3h,
//! int/uint/int64), so a stage authored with doubles reads the same.

use openusd::sdf::Value;

pub(crate) fn points(value: &Value) -> Option<Vec<[f64; 3]>> {
    Some(match value {
        Value::Vec3fVec(v) => v.iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect(),
        Value::Vec3dVec(v) => v.iter().map(|p| [p.x, p.y, p.z]).collect(),
        Value::Vec3hVec(v) => v.iter().map(|p| [p.x.to_f64(), p.y.to_f64(), p.z.to_f64()]).collect(),
        _ => return None,
    })
}

/// Integers as `i64` (so a negative index can be reported, not wrapped).
pub(crate) fn ints(value: &Value) -> Option<Vec<i64>> {
    Some(match value {
        Value::IntVec(v) => v.iter().map(|&i| i as i64).collect(),
        Value::UintVec(v) => v.iter().map(|&i| i as i64).collect(),
        Value::Int64Vec(v) => v.clone(),
        Value::Uint64Vec(v) => v.iter().map(|&i| i.min(i64::MAX as u64) as i64).collect(),
        _ => return None,
    })
}

pub(crate) fn floats(value: &Value) -> Option<Vec<f64>> {
    Some(match value {
        Value::FloatVec(v) => v.iter().map(|&x| x as f64).collect(),
        Value::DoubleVec(v) => v.clone(),
        Value::HalfVec(v) => v.iter().map(|x| x.to_f64()).collect(),
        _ => return None,
    })
}

pub(crate) fn scalar(value: &Value) -> Option<f64> {
    Some(match value {
        Value::Float(x) => *x as f64,
        Value::Double(x) => *x,
        Value::Half(x) => x.to_f64(),
        Value::Int(x) => *x as f64,
        _ => return None,
    })
}

pub(crate) fn token(value: &Value) -> Option<String> {
    match value {
        Value::Token(t) => Some(t.as_str().to_string()),
        Value::String(s) => Some(s.clone()),
        _ => None,
    }
}

pub(crate) fn tokens(value: &Value) -> Option<Vec<String>> {
    match value {
        Value::TokenVec(v) => Some(v.iter().map(|t| t.as_str().to_string()).collect()),
        Value::StringVec(v) => Some(v.clone()),
        _ => None,
    }
}

/// A short name for a value's type, for error messages.
pub(crate) fn kind(value: &Value) -> String {
    let s = format!("{value:?}");
    s.split(['(', ' ', '{']).next().unwrap_or("value").to_string()
}

/// A 3-vector (`float3`, `double3`, `half3` and their roles).
pub(crate) fn vec3(value: &Value) -> Option<[f64; 3]> {
    Some(match value {
        Value::Vec3f(v) => [v.x as f64, v.y as f64, v.z as f64],
        Value::Vec3d(v) => [v.x, v.y, v.z],
        Value::Vec3h(v) => [v.x.to_f64(), v.y.to_f64(), v.z.to_f64()],
        _ => return None,
    })
}

/// A quaternion as `[w, x, y, z]` (`quatf`, `quatd`, `quath`).
pub(crate) fn quat(value: &Value) -> Option<[f64; 4]> {
    Some(match value {
        Value::Quatf(q) => [q.w as f64, q.x as f64, q.y as f64, q.z as f64],
        Value::Quatd(q) => [q.w, q.x, q.y, q.z],
        Value::Quath(q) => [q.w.to_f64(), q.x.to_f64(), q.y.to_f64(), q.z.to_f64()],
        _ => return None,
    })
}

/// An integer (`int`, `uint`, `int64`, `uint64`) as `i64`.
pub(crate) fn int(value: &Value) -> Option<i64> {
    Some(match value {
        Value::Int(i) => *i as i64,
        Value::Uint(i) => *i as i64,
        Value::Int64(i) => *i,
        Value::Uint64(i) => (*i).min(i64::MAX as u64) as i64,
        _ => return None,
    })
}

pub(crate) fn bool(value: &Value) -> Option<bool> {
    match value {
        Value::Bool(b) => Some(*b),
        _ => None,
    }
}
