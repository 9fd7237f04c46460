//! The subset of YAML that Kalibr's `camchain.yaml` and OpenCV's FileStorage write: nested
//! `key: value` mappings by indentation, scalars, and `[a, b, …]` lists (which may run over
//! several lines) or block lists (`- item` lines under `key:`, read as the list `[item, …]`).
//! Tags (`!!opencv-matrix`), `%YAML` directives, `---` and comments are skipped.

/// Every value of the document under its dotted key path (`cam0.intrinsics`, `K.data`).
#[derive(Debug, Default)]
pub struct FlatYaml {
    /// (key path, value text, 1-based line number), in file order.
    entries: Vec<(String, String, usize)>,
}

fn strip_comment(line: &str) -> &str {
    match line.find(" #") {
        Some(k) => &line[..k],
        None if line.trim_start().starts_with('#') => "",
        None => line,
    }
}

fn bracket_depth(s: &str) -> i32 {
    s.chars().map(|c| (c == '[') as i32 - (c == ']') as i32).sum()
}

impl FlatYaml {
    pub fn parse(text: &str) -> Result<FlatYaml, String> {
        let mut doc = FlatYaml::default();
        // Open mappings: (indent, key).
        let mut stack: Vec<(usize, String)> = Vec::new();
        let mut open_list: Option<usize> = None;
        for (n, raw) in text.lines().enumerate() {
            let line = strip_comment(raw).trim_end();
            let content = line.trim_start();
            if let Some(k) = open_list {
                let entry = &mut doc.entries[k];
                entry.1.push(' ');
                entry.1.push_str(content);
                if bracket_depth(&entry.1) <= 0 {
                    open_list = None;
                }
                continue;
            }
            if let Some(version) = content.strip_prefix("%YAML").map(|v| v.trim_start_matches([':', ' ']))
                && !version.starts_with("1.")
            {
                return Err(format!(
                    "line {}: %YAML {version}: this build reads YAML 1.x (OpenCV's FileStorage)",
                    n + 1
                ));
            }
            if content.is_empty() || content.starts_with('%') || content.starts_with("---") {
                continue;
            }
            let indent = line.len() - content.len();
            if let Some(item) = content.strip_prefix("- ").or(if content == "-" { Some("") } else { None }) {
                // A block list item belongs to the last open key at or left of its indent.
                while stack.last().is_some_and(|(i, _)| *i > indent) {
                    stack.pop();
                }
                let parent = stack.iter().map(|(_, k)| k.as_str()).collect::<Vec<_>>().join(".");
                match doc.entries.last_mut() {
                    Some(last) if last.0 == parent && last.1.ends_with(']') => {
                        last.1.pop();
                        last.1.push_str(&format!(", {}]", item.trim()));
                    }
                    _ => doc.entries.push((parent, format!("[{}]", item.trim()), n + 1)),
                }
                continue;
            }
            let (key, value) = match content.split_once(": ") {
                Some((k, v)) => (k.trim(), v.trim()),
                None if content.ends_with(':') => (content.trim_end_matches(':').trim(), ""),
                None => return Err(format!("line {}: expected \"key: value\", got {content:?}", n + 1)),
            };
            while stack.last().is_some_and(|(i, _)| *i >= indent) {
                stack.pop();
            }
            let path: Vec<&str> = stack.iter().map(|(_, k)| k.as_str()).chain([key]).collect();
            let path = path.join(".");
            if value.is_empty() || value.starts_with("!!") {
                stack.push((indent, key.to_string()));
                continue;
            }
            if bracket_depth(value) > 0 {
                open_list = Some(doc.entries.len());
            }
            doc.entries.push((path, value.to_string(), n + 1));
        }
        if let Some(k) = open_list {
            return Err(format!("line {}: {}: the list is not closed with ']'", doc.entries[k].2, doc.entries[k].0));
        }
        Ok(doc)
    }

    fn get(&self, key: &str) -> Result<&(String, String, usize), String> {
        self.entries.iter().find(|e| e.0 == key).ok_or_else(|| format!("{key}: missing"))
    }

    /// Whether any key is `prefix` or starts with `prefix.`.
    pub fn has_prefix(&self, prefix: &str) -> bool {
        self.entries.iter().any(|e| e.0 == prefix || e.0.starts_with(&format!("{prefix}.")))
    }

    /// The distinct first components of the keys, in file order.
    pub fn top_keys(&self) -> Vec<String> {
        let mut keys: Vec<String> = Vec::new();
        for e in &self.entries {
            let top = e.0.split('.').next().unwrap_or_default().to_string();
            if !keys.contains(&top) {
                keys.push(top);
            }
        }
        keys
    }

    /// A scalar's text, quotes removed.
    pub fn scalar(&self, key: &str) -> Result<String, String> {
        Ok(self.get(key)?.1.trim_matches(|c| c == '"' || c == '\'').to_string())
    }

    /// A finite number.
    pub fn number(&self, key: &str) -> Result<f64, String> {
        let (_, v, line) = self.get(key)?;
        parse_number(v).ok_or_else(|| format!("line {line}: {key}: {v:?} is not a finite number"))
    }

    /// The numbers of an OpenCV matrix `name` (its `data`, of `len` entries if given), checked
    /// against its `rows` × `cols` and its element type `dt` (floating point) where written.
    pub fn matrix(&self, name: &str, len: Option<usize>) -> Result<Vec<f64>, String> {
        let data = self.numbers(&format!("{name}.data"), len)?;
        if let (Ok(rows), Ok(cols)) = (self.number(&format!("{name}.rows")), self.number(&format!("{name}.cols"))) {
            let whole = |v: f64| v.fract() == 0.0 && (0.0..=1e6).contains(&v);
            if !(whole(rows) && whole(cols) && rows * cols == data.len() as f64) {
                return Err(format!("{name}: rows × cols = {rows} × {cols}, but its data has {} numbers", data.len()));
            }
        }
        if let Ok(dt) = self.scalar(&format!("{name}.dt"))
            && !matches!(dt.as_str(), "d" | "f")
        {
            return Err(format!("{name}.dt: {dt:?} is not a floating-point element type (d or f)"));
        }
        Ok(data)
    }

    /// A `[a, b, …]` list of finite numbers, of `len` entries if given.
    pub fn numbers(&self, key: &str, len: Option<usize>) -> Result<Vec<f64>, String> {
        let (_, v, line) = self.get(key)?;
        let inner = v
            .trim()
            .strip_prefix('[')
            .and_then(|s| s.strip_suffix(']'))
            .ok_or_else(|| format!("line {line}: {key}: expected a [a, b, …] list, got {v:?}"))?;
        let values: Vec<f64> = inner
            .split(',')
            .map(str::trim)
            .filter(|t| !t.is_empty())
            .map(|t| parse_number(t).ok_or_else(|| format!("line {line}: {key}: {t:?} is not a finite number")))
            .collect::<Result<_, _>>()?;
        match len {
            Some(n) if values.len() != n => {
                Err(format!("line {line}: {key}: expected {n} numbers, got {}", values.len()))
            }
            _ => Ok(values),
        }
    }
}

/// A finite number as YAML and OpenCV write them (`1.`, `-2.5e-03`).
fn parse_number(t: &str) -> Option<f64> {
    t.trim().parse::<f64>().ok().filter(|x| x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A matrix's rows × cols must match its data and its type be floating point; a YAML
    /// version other than 1.x is refused at its line.
    #[test]
    fn matrices_agree_with_their_headers() {
        let doc = |rows: &str, dt: &str| {
            format!(
                "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: {rows}\n   cols: 2\n   dt: {dt}\n   data: [ 1., 2., 3., 4. ]\n"
            )
        };
        let ok = FlatYaml::parse(&doc("2", "d")).unwrap();
        assert_eq!(ok.matrix("K", Some(4)).unwrap(), vec![1.0, 2.0, 3.0, 4.0]);
        let err = FlatYaml::parse(&doc("3", "d")).unwrap().matrix("K", None).unwrap_err();
        assert!(err.contains("rows × cols = 3 × 2") && err.contains("4 numbers"), "{err}");
        let err = FlatYaml::parse(&doc("2", "q")).unwrap().matrix("K", None).unwrap_err();
        assert!(err.contains("K.dt: \"q\""), "{err}");
        let err = FlatYaml::parse("%YAML:9.9\nx: 1\n").err().unwrap();
        assert!(err.contains("line 1") && err.contains("9.9"), "{err}");
    }

    #[test]
    fn reads_nested_keys_lists_over_lines_and_skips_the_rest() {
        let text = "%YAML:1.0\n---\n# comment\ncam0:\n  T_cn_cnm1:\n  - [1, 0]\n  - [0, 1]\n  resolution:\n  - 752\n  - 480\n  intrinsics: [1.5, 2.,\n     3e-1]  # note\n  \
                    rostopic: /a/b\nK: !!opencv-matrix\n   rows: 1\n   data: [ 4 ]\ncam1:\n  x: 2\n";
        let doc = FlatYaml::parse(text).unwrap();
        assert_eq!(doc.numbers("cam0.intrinsics", Some(3)).unwrap(), vec![1.5, 2.0, 0.3]);
        assert_eq!(doc.scalar("cam0.rostopic").unwrap(), "/a/b");
        assert_eq!(doc.numbers("cam0.resolution", Some(2)).unwrap(), vec![752.0, 480.0]);
        assert!(doc.numbers("cam0.T_cn_cnm1", None).unwrap_err().contains("\"[1\" is not a finite number"));
        assert_eq!(doc.numbers("K.data", None).unwrap(), vec![4.0]);
        assert_eq!(doc.number("K.rows").unwrap(), 1.0);
        assert_eq!(doc.number("cam1.x").unwrap(), 2.0);
        assert_eq!(doc.top_keys(), vec!["cam0", "K", "cam1"]);
        assert!(doc.numbers("cam0.intrinsics", Some(4)).unwrap_err().contains("line 11: cam0.intrinsics: expected 4"));
        assert!(doc.number("cam0.rostopic").unwrap_err().contains("not a finite number"));
        assert_eq!(doc.number("cam9.x").unwrap_err(), "cam9.x: missing");
        assert!(FlatYaml::parse("a: [1, 2\n").unwrap_err().contains("line 1: a: the list is not closed"));
        assert!(FlatYaml::parse("just text\n").unwrap_err().contains("line 1: expected \"key: value\""));
    }
}
