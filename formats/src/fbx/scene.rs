//! The objects, connections, property templates and global settings of a parsed FBX file, and typed reads of
//! their properties with errors naming the object.

use std::collections::HashMap;
use std::path::Path;

use super::binary::{self, Node, Prop};
use crate::error::{DataError, Result};
use crate::skeletal::Mat;

/// One object of the `Objects` section.
pub(super) struct Object<'a> {
    pub(super) name: &'a str,
    pub(super) class: &'a str,
    pub(super) node: &'a Node,
}

pub(super) struct Scene<'a> {
    pub(super) path: &'a Path,
    pub(super) objects: HashMap<i64, Object<'a>>,
    /// `(child, parent, property)` in file order.
    pub(super) links: Vec<(i64, i64, Option<&'a str>)>,
    pub(super) settings: Option<&'a Node>,
    /// Properties70 of each object type's property template.
    pub(super) templates: HashMap<&'a str, &'a Node>,
}

/// `Properties70` value list (after name, type, label and flags) of property `name` of `node`.
pub(super) fn p70<'a>(node: &'a Node, name: &str) -> Option<&'a [Prop]> {
    let block = if node.name == "Properties70" {
        node
    } else {
        node.child("Properties70")?
    };
    block
        .all("P")
        .find(|p| p.props.first().and_then(Prop::str) == Some(name))
        .map(|p| &p.props[p.props.len().min(4)..])
}

impl<'a> Scene<'a> {
    pub(super) fn new(path: &'a Path, doc: &'a binary::Document) -> Self {
        let top = |n: &str| doc.nodes.iter().find(|x| x.name == n);
        let mut objects = HashMap::new();
        for node in top("Objects").map(|o| o.children.as_slice()).unwrap_or_default() {
            let (Some(id), Some(name)) = (
                node.props.first().and_then(Prop::int),
                node.props.get(1).and_then(Prop::str),
            ) else {
                continue;
            };
            let name = name.split("\0\u{1}").next().unwrap_or_default();
            let class = node.props.get(2).and_then(Prop::str).unwrap_or_default();
            objects.insert(id, Object { name, class, node });
        }
        let mut links = Vec::new();
        for c in top("Connections").map(|o| o.children.as_slice()).unwrap_or_default() {
            if let (Some(child), Some(parent)) =
                (c.props.get(1).and_then(Prop::int), c.props.get(2).and_then(Prop::int))
            {
                links.push((child, parent, c.props.get(3).and_then(Prop::str)));
            }
        }
        let mut templates = HashMap::new();
        for t in top("Definitions").iter().flat_map(|d| d.all("ObjectType")) {
            if let (Some(kind), Some(p)) = (
                t.props.first().and_then(Prop::str),
                t.child("PropertyTemplate").and_then(|p| p.child("Properties70")),
            ) {
                templates.insert(kind, p);
            }
        }
        let settings = top("GlobalSettings").and_then(|g| g.child("Properties70"));
        Scene {
            path,
            objects,
            links,
            settings,
            templates,
        }
    }

    pub(super) fn err(&self, field: impl Into<String>, reason: impl Into<String>) -> DataError {
        DataError::new(self.path, field, reason)
    }

    /// Ids of the objects of node kind `kind` linked to `parent` (with property `prop`, or by object when `None`),
    /// in file order.
    pub(super) fn children(&self, parent: i64, kind: &str, prop: Option<&str>) -> Vec<i64> {
        self.links
            .iter()
            .filter(|(c, p, pr)| {
                *p == parent && *pr == prop && self.objects.get(c).is_some_and(|o| o.node.name == kind)
            })
            .map(|l| l.0)
            .collect()
    }

    /// Objects of node kind `kind`, sorted by id for a deterministic order.
    pub(super) fn of_kind(&self, kind: &str) -> Vec<i64> {
        let mut ids: Vec<i64> = self
            .objects
            .iter()
            .filter(|(_, o)| o.node.name == kind)
            .map(|(i, _)| *i)
            .collect();
        ids.sort_unstable();
        ids
    }

    /// Property `name` of object `id`: its own value, else its type's template's.
    pub(super) fn prop(&self, id: i64, name: &str) -> Option<&'a [Prop]> {
        let o = &self.objects[&id];
        p70(o.node, name).or_else(|| self.templates.get(o.node.name.as_str()).and_then(|t| p70(t, name)))
    }

    pub(super) fn vec3(&self, id: i64, name: &str, default: [f64; 3]) -> Result<[f64; 3]> {
        let Some(v) = self.prop(id, name) else {
            return Ok(default);
        };
        let f = |k: usize| v.get(k).and_then(Prop::float).filter(|x| x.is_finite());
        match (f(0), f(1), f(2)) {
            (Some(x), Some(y), Some(z)) => Ok([x, y, z]),
            _ => Err(self.err(self.field(id, name), "not three finite numbers")),
        }
    }

    pub(super) fn setting(&self, name: &str) -> Option<&'a Prop> {
        self.settings.and_then(|s| p70(s, name)).and_then(|v| v.first())
    }

    /// `Kind "name" what`: the field an error about object `id` names.
    fn field(&self, id: i64, what: &str) -> String {
        let o = &self.objects[&id];
        format!("{} {:?} {what}", o.node.name, o.name)
    }

    /// The first property of object `id`'s child node `name`, picked by `pick` (`None` when the node is missing;
    /// an error saying `expected` when it holds something else).
    fn child_prop<T: ?Sized>(
        &self,
        id: i64,
        name: &str,
        expected: &str,
        pick: impl Fn(&'a Prop) -> Option<&'a T>,
    ) -> Result<Option<&'a T>> {
        match self.objects[&id].node.child(name).and_then(|n| n.props.first()) {
            None => Ok(None),
            Some(p) => pick(p)
                .map(Some)
                .ok_or_else(|| self.err(self.field(id, name), format!("not an array of {expected}"))),
        }
    }

    /// The float array of object `id`'s child node `name` (empty when the node is missing).
    pub(super) fn array(&self, id: i64, name: &str) -> Result<&'a [f64]> {
        let pick = |p: &'a Prop| match p {
            Prop::Floats(v) => Some(v.as_slice()),
            _ => None,
        };
        Ok(self.child_prop(id, name, "numbers", pick)?.unwrap_or_default())
    }

    /// The integer array of object `id`'s child node `name` (empty when the node is missing).
    pub(super) fn ints(&self, id: i64, name: &str) -> Result<&'a [i64]> {
        let pick = |p: &'a Prop| match p {
            Prop::Ints(v) => Some(v.as_slice()),
            _ => None,
        };
        Ok(self.child_prop(id, name, "integers", pick)?.unwrap_or_default())
    }

    pub(super) fn matrix(&self, id: i64, name: &str) -> Result<Option<Mat>> {
        let a = self.array(id, name)?;
        if a.is_empty() {
            return Ok(None);
        }
        if a.len() != 16 || a.iter().any(|x| !x.is_finite()) {
            return Err(self.err(self.field(id, name), "not 16 finite numbers"));
        }
        // Stored column after column.
        Ok(Some(std::array::from_fn(|r| std::array::from_fn(|c| a[c * 4 + r]))))
    }
}
