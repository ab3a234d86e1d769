//! The helper library `templates/ops.wgsl` as data: which helper implements
//! each operator (the one WGSL fact about operators, kept here so that `lang`
//! knows no WGSL), each helper's text and the helpers it calls, and the
//! linker that gives a kernel exactly the helpers it needs.

use std::collections::BTreeSet;
use std::sync::OnceLock;

use crate::lang::{BinaryOp, PairOp, UnaryOp};

/// The operator helpers, verbatim.
pub const OPS_WGSL: &str = include_str!("../../templates/ops.wgsl");

/// One function of the library.
struct Function {
    name: String,
    /// Its text, with the comments before it.
    text: String,
    /// The library's other functions it calls (indices).
    calls: Vec<usize>,
}

/// The library: its prelude (comments, constants, the flag variable) and its
/// functions, in file order. Read once from `templates/ops.wgsl`.
struct Library {
    prelude: String,
    functions: Vec<Function>,
}

fn library() -> &'static Library {
    static LIBRARY: OnceLock<Library> = OnceLock::new();
    LIBRARY.get_or_init(|| {
        let mut prelude = String::new();
        let mut items: Vec<(String, String)> = Vec::new();
        for line in OPS_WGSL.lines() {
            if let Some(rest) = line.strip_prefix("fn ") {
                let name = rest.split('(').next().unwrap_or_default().trim().to_string();
                items.push((name, String::new()));
            } else if line.starts_with("//") && items.last().is_some_and(|(_, body)| body.trim_end().ends_with('}')) {
                // A comment between functions belongs to the next one.
                items.push((String::new(), String::new()));
            }
            match items.last_mut() {
                Some((_, body)) => {
                    body.push_str(line);
                    body.push('\n');
                }
                None => {
                    prelude.push_str(line);
                    prelude.push('\n');
                }
            }
        }
        // Leading comments (items without a name) belong to the function after them.
        let mut functions: Vec<Function> = Vec::new();
        let mut pending = String::new();
        for (name, body) in items {
            if name.is_empty() {
                pending.push_str(&body);
            } else {
                functions.push(Function { name, text: std::mem::take(&mut pending) + &body, calls: Vec::new() });
            }
        }
        // Who calls whom, read from the parsed module, not from the text.
        let module = naga::front::wgsl::parse_str(OPS_WGSL)
            .unwrap_or_else(|e| panic!("templates/ops.wgsl parses: {}", e.emit_to_string(OPS_WGSL)));
        let index = |name: &str| functions.iter().position(|f| f.name == name);
        let calls: Vec<Vec<usize>> = functions
            .iter()
            .map(|f| {
                let (_, function) = module
                    .functions
                    .iter()
                    .find(|(_, g)| g.name.as_deref() == Some(f.name.as_str()))
                    .unwrap_or_else(|| panic!("naga reads `{}` in templates/ops.wgsl", f.name));
                let mut callees = BTreeSet::new();
                called(&function.body, &mut callees);
                callees.iter().filter_map(|&h| index(module.functions[h].name.as_deref()?)).collect()
            })
            .collect();
        for (f, calls) in functions.iter_mut().zip(calls) {
            f.calls = calls;
        }
        Library { prelude, functions }
    })
}

/// The functions a block calls, in its nested blocks too.
fn called(block: &naga::Block, out: &mut BTreeSet<naga::Handle<naga::Function>>) {
    use naga::Statement;
    for statement in block.iter() {
        match statement {
            Statement::Call { function, .. } => {
                out.insert(*function);
            }
            Statement::Block(inner) => called(inner, out),
            Statement::If { accept, reject, .. } => {
                called(accept, out);
                called(reject, out);
            }
            Statement::Switch { cases, .. } => cases.iter().for_each(|c| called(&c.body, out)),
            Statement::Loop { body, continuing, .. } => {
                called(body, out);
                called(continuing, out);
            }
            _ => {}
        }
    }
}

/// The prelude and exactly the helpers `needs` names and the ones they call,
/// in library order: a smaller module compiles faster, and a kernel reads as
/// what it computes. A name the library lacks is a filterjit bug.
pub fn link(needs: impl IntoIterator<Item = String>) -> String {
    let library = library();
    let mut used = vec![false; library.functions.len()];
    let mut frontier: Vec<usize> = needs
        .into_iter()
        .map(|name| {
            library
                .functions
                .iter()
                .position(|f| f.name == name)
                .unwrap_or_else(|| panic!("templates/ops.wgsl has no helper `{name}`"))
        })
        .collect();
    while let Some(k) = frontier.pop() {
        if !std::mem::replace(&mut used[k], true) {
            frontier.extend(library.functions[k].calls.iter().copied());
        }
    }
    let mut out = library.prelude.clone();
    for (f, _) in library.functions.iter().zip(&used).filter(|(_, used)| **used) {
        out.push_str(&f.text);
    }
    out
}

/// The names of every helper of the library.
pub fn names() -> BTreeSet<String> {
    library().functions.iter().map(|f| f.name.clone()).collect()
}

/// An operator implemented by a helper function of `templates/ops.wgsl`.
pub trait Helper {
    /// The helper's name: `fj_` and the operator's name (lower case).
    fn helper(&self) -> String;
}

impl Helper for UnaryOp {
    fn helper(&self) -> String {
        format!("fj_{}", self.name().to_ascii_lowercase())
    }
}

impl Helper for BinaryOp {
    fn helper(&self) -> String {
        format!("fj_{}", self.name())
    }
}

impl Helper for PairOp {
    fn helper(&self) -> String {
        format!("fj_{}", self.name().to_ascii_lowercase())
    }
}

#[cfg(test)]
mod tests {
    use super::OPS_WGSL;
    use super::*;

    /// Every operator's helper is defined in `templates/ops.wgsl`, under a valid identifier.
    #[test]
    fn every_operator_has_its_helper() {
        let names: Vec<String> = UnaryOp::ALL
            .iter()
            .map(Helper::helper)
            .chain(BinaryOp::ALL.iter().map(Helper::helper))
            .chain(PairOp::ALL.iter().map(Helper::helper))
            .collect();
        for name in names {
            assert!(name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'), "{name}");
            assert!(OPS_WGSL.contains(&format!("fn {name}(")), "templates/ops.wgsl defines no {name}");
        }
    }
}
