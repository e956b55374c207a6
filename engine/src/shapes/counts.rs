//! Numbers per kind: objects in a scene, intersection tests in a render.

use super::{KINDS, ShapeKind};
use serde::ser::{Serialize, SerializeMap, Serializer};
use std::ops::AddAssign;

/// A count per [`ShapeKind`], indexed by kind. Serialized as a map from
/// kind name to count, in kind order (`{"sphere": 3, "polygon": 0, ...}`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KindCounts(pub [u64; KINDS]);

impl KindCounts {
    #[inline(always)]
    pub fn add(&mut self, k: ShapeKind) {
        self.0[k.index()] += 1;
    }

    #[inline]
    pub fn add_n(&mut self, k: ShapeKind, n: u64) {
        self.0[k.index()] += n;
    }

    pub fn get(&self, k: ShapeKind) -> u64 {
        self.0[k.index()]
    }

    pub fn total(&self) -> u64 {
        self.0.iter().sum()
    }

    /// (kind name, count) in kind order.
    pub fn named(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        ShapeKind::ALL.iter().map(|&k| (k.name(), self.get(k)))
    }

    /// Adds counts given by kind name (as they travel between processes);
    /// the first unknown name is an error.
    pub fn add_named<'a>(
        &mut self,
        named: impl IntoIterator<Item = (&'a str, u64)>,
    ) -> Result<(), String> {
        for (name, n) in named {
            let k = ShapeKind::ALL
                .iter()
                .find(|k| k.name() == name)
                .ok_or_else(|| format!("unknown primitive kind '{name}'"))?;
            self.add_n(*k, n);
        }
        Ok(())
    }
}

impl AddAssign for KindCounts {
    fn add_assign(&mut self, o: Self) {
        for (a, b) in self.0.iter_mut().zip(o.0) {
            *a += b;
        }
    }
}

impl Serialize for KindCounts {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(KINDS))?;
        for (name, n) in self.named() {
            m.serialize_entry(name, &n)?;
        }
        m.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn by_kind_and_by_name() {
        let mut c = KindCounts::default();
        c.add(ShapeKind::Cone);
        c.add_n(ShapeKind::Sphere, 4);
        assert_eq!(c.total(), 5);
        let json: serde_json::Value = serde_json::to_value(c).unwrap();
        let map = json.as_object().unwrap();
        assert_eq!(map.len(), KINDS);
        assert_eq!(map["sphere"], 4);
        assert_eq!(map["polygon"], 0);
        assert_eq!(map["cone"], 1);
        // In kind order.
        let text = serde_json::to_string(&c).unwrap();
        assert!(
            text.starts_with(r#"{"sphere":4,"polygon":0,"patch":0,"cone":1"#),
            "{text}"
        );
        let mut d = KindCounts::default();
        d.add_named(c.named()).unwrap();
        assert_eq!(c, d);
        assert!(d.add_named([("blob", 1)]).is_err());
    }
}
