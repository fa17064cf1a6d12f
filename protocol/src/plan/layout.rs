//! The planner messages' layout as data, the one place it is written: every header field's
//! name, offset and type ([`REQUEST_FIELDS`], [`ANSWER_FIELDS`]), every array of a request
//! ([`REQUEST_ARRAYS`]) and the rows of its two table arrays ([`TARGET_ROW_FIELDS`],
//! [`OTHER_ROW_FIELDS`]).
//!
//! The writers and the reader of the parent module place every header field where these
//! tables say, and check (in debug builds) that they go through the fields in the tables'
//! order. The two other descriptions of the layout are checked against these tables by this
//! module's tests, which name the first field that differs: the tables of `docs/python.md`
//! and the numpy dtypes of `python/setfleet/layout.py`. They are checked rather than
//! generated because both are written for a reader (the docs say what each field means, the
//! Python module is the package's reference), and the layout changes rarely (its version is
//! in every message), so a hand edit guided by a failing test costs less than a generator.

use super::ARRAYS;
use Scalar::{F32, F64, U8, U16, U32, U64};

/// The type of a number of the layout, stored little-endian.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scalar {
    /// `u8`.
    U8,
    /// `u16`.
    U16,
    /// `u32`.
    U32,
    /// `u64`.
    U64,
    /// `f32`.
    F32,
    /// `f64`.
    F64,
}

impl Scalar {
    /// Its size in bytes.
    pub const fn bytes(self) -> usize {
        match self {
            Scalar::U8 => 1,
            Scalar::U16 => 2,
            Scalar::U32 | Scalar::F32 => 4,
            Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// Its name in `docs/python.md`'s header tables: `u32`.
    pub const fn name(self) -> &'static str {
        match self {
            Scalar::U8 => "u8",
            Scalar::U16 => "u16",
            Scalar::U32 => "u32",
            Scalar::U64 => "u64",
            Scalar::F32 => "f32",
            Scalar::F64 => "f64",
        }
    }

    /// Its numpy dtype: `<u4` (`u1` for a byte, which has no order).
    pub const fn dtype(self) -> &'static str {
        match self {
            Scalar::U8 => "u1",
            Scalar::U16 => "<u2",
            Scalar::U32 => "<u4",
            Scalar::U64 => "<u8",
            Scalar::F32 => "<f4",
            Scalar::F64 => "<f8",
        }
    }
}

/// What a header field holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldType {
    /// One number.
    Number(Scalar),
    /// The request's array table: an `(offset, length)` pair of `u64` per array, [`ARRAYS`]
    /// pairs.
    ArrayTable,
}

impl FieldType {
    /// Its size in bytes.
    pub const fn bytes(self) -> usize {
        match self {
            FieldType::Number(s) => s.bytes(),
            FieldType::ArrayTable => 16 * ARRAYS,
        }
    }
}

/// A field of a header or of a row of a table array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// Its name, as `docs/python.md` and the numpy dtypes give it.
    pub name: &'static str,
    /// Its offset in bytes from the start of the header (or of the row).
    pub offset: usize,
    /// What it holds.
    pub ty: FieldType,
    /// Whether `docs/python.md` gives it on the row of the field before it, as one vector
    /// (`x`, `y`, `z`, `yaw`).
    pub joined: bool,
}

impl Field {
    /// Where it ends: the offset of the byte after it.
    pub const fn end(&self) -> usize {
        self.offset + self.ty.bytes()
    }
}

/// A field of one number that starts a row of `docs/python.md`'s table.
const fn number(name: &'static str, offset: usize, scalar: Scalar) -> Field {
    Field {
        name,
        offset,
        ty: FieldType::Number(scalar),
        joined: false,
    }
}

/// A field of one number on the row of the field before it.
const fn joined(name: &'static str, offset: usize, scalar: Scalar) -> Field {
    Field {
        joined: true,
        ..number(name, offset, scalar)
    }
}

/// The request's header, [`super::REQUEST_HEADER_BYTES`] bytes: these fields, then zeros.
pub const REQUEST_FIELDS: &[Field] = &[
    number("magic", 0, U32),
    number("version", 4, U16),
    number("header_bytes", 6, U16),
    number("run_tag", 8, U64),
    number("step", 16, U64),
    number("round", 24, U64),
    number("total_steps", 32, U64),
    number("uav", 40, U32),
    number("fleet_size", 44, U32),
    number("steps_per_period", 48, U32),
    number("horizon", 52, U32),
    number("deadline_ms", 56, U32),
    number("flags", 60, U32),
    number("time_s", 64, F64),
    number("dt_s", 72, F64),
    number("speed_mps", 80, F64),
    number("max_yaw_rate_rps", 88, F64),
    number("x", 96, F64),
    joined("y", 104, F64),
    joined("z", 112, F64),
    joined("yaw", 120, F64),
    number("camera_aperture_rad", 128, F64),
    number("camera_tilt_rad", 136, F64),
    number("camera_rows", 144, U32),
    joined("camera_cols", 148, U32),
    number("plan_origin_x", 152, F64),
    joined("plan_origin_y", 160, F64),
    number("plan_cell_m", 168, F64),
    number("plan_nx", 176, U32),
    joined("plan_ny", 180, U32),
    number("count_cell_m2", 184, F64),
    number("oem_origin_x", 192, F64),
    joined("oem_origin_y", 200, F64),
    number("oem_cell_m", 208, F64),
    number("oem_nx", 216, U32),
    joined("oem_ny", 220, U32),
    number("border_half_m", 224, F64),
    number("undetected_m2", 232, F64),
    number("targets_m2", 240, F64),
    number("n_increments", 248, U32),
    number("n_targets", 252, U32),
    number("n_others", 256, U32),
    number("n_poses", 260, U32),
    number("n_fleet", 264, U32),
    number("n_target_counts", 268, U32),
    Field {
        name: "arrays",
        offset: 272,
        ty: FieldType::ArrayTable,
        joined: false,
    },
];

/// The answer's header, [`super::ANSWER_HEADER_BYTES`] bytes.
pub const ANSWER_FIELDS: &[Field] = &[
    number("magic", 0, U32),
    number("version", 4, U16),
    number("kind", 6, U16),
    number("step", 8, U64),
    number("uav", 16, U32),
    number("n_increments", 20, U32),
    number("n_poses", 24, U32),
    number("reserved", 28, U32),
    number("yaw_ref", 32, F64),
    number("planner_ns", 40, U64),
];

/// A row of the request's `targets` array: one identified car.
pub const TARGET_ROW_FIELDS: &[Field] = &[
    number("id", 0, U32),
    number("x0", 4, U32),
    number("y0", 8, U32),
    number("w", 12, U32),
    number("h", 16, U32),
    number("first", 20, U32),
    number("area_m2", 24, F64),
];

/// A row of the request's `others` array: the plan of a UAV ahead in the token.
pub const OTHER_ROW_FIELDS: &[Field] = &[
    number("uav", 0, U32),
    number("n_poses", 4, U32),
    number("first", 8, U32),
    number("pad", 12, U32),
];

/// What one element of a request's array is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Element {
    /// A number.
    Number(Scalar),
    /// A row of these fields.
    Row(&'static [Field]),
}

impl Element {
    /// Its size in bytes.
    pub const fn bytes(self) -> usize {
        match self {
            Element::Number(s) => s.bytes(),
            Element::Row(fields) => row_bytes(fields),
        }
    }
}

/// The bytes of a row of `fields`: where its last field ends.
pub const fn row_bytes(fields: &[Field]) -> usize {
    match fields.last() {
        Some(last) => last.end(),
        None => 0,
    }
}

/// An array of a request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RequestArray {
    /// Its name, as `docs/python.md` and `layout.py`'s `ARRAY_NAMES` give it.
    pub name: &'static str,
    /// What its elements are.
    pub element: Element,
}

/// The arrays of a request, in their order after the header ([`super::ArrayId`]'s).
pub const REQUEST_ARRAYS: [RequestArray; ARRAYS] = [
    array("increments", Element::Number(F64)),
    array("undetected", Element::Number(U16)),
    array("obstacle_neighbourhood", Element::Number(U16)),
    array("unseen", Element::Number(U16)),
    array("recently_hidden", Element::Number(U16)),
    array("targets", Element::Row(TARGET_ROW_FIELDS)),
    array("target_counts", Element::Number(U16)),
    array("oem_height", Element::Number(F32)),
    array("oem_status", Element::Number(U8)),
    array("others", Element::Row(OTHER_ROW_FIELDS)),
    array("poses", Element::Number(F64)),
    array("fleet", Element::Number(U32)),
];

const fn array(name: &'static str, element: Element) -> RequestArray {
    RequestArray { name, element }
}

/// A number a header holds.
pub(super) trait Number: Copy {
    /// Its type in the tables.
    const SCALAR: Scalar;
    /// Writes it little-endian at the start of `out`.
    fn write_le(self, out: &mut [u8]);
}

macro_rules! number_impl {
    ($($t:ty => $s:expr),*) => {$(
        impl Number for $t {
            const SCALAR: Scalar = $s;
            fn write_le(self, out: &mut [u8]) {
                let bytes = self.to_le_bytes();
                out[..bytes.len()].copy_from_slice(&bytes);
            }
        }
    )*};
}

number_impl!(u16 => U16, u32 => U32, u64 => U64, f64 => F64);

/// Writes a header field after field, in the order of its table, each at the offset the table
/// gives; in debug builds it checks each field's name and type against the table.
pub(super) struct HeaderWriter<'a> {
    buf: &'a mut [u8],
    fields: &'static [Field],
    next: usize,
}

impl<'a> HeaderWriter<'a> {
    /// A writer of the header of `fields` at the start of `buf`.
    pub(super) fn new(buf: &'a mut [u8], fields: &'static [Field]) -> Self {
        Self {
            buf,
            fields,
            next: 0,
        }
    }

    /// The next field, which the caller says is `name` of type `ty`.
    fn field(&mut self, name: &str, ty: FieldType) -> Field {
        let field = self.fields[self.next];
        debug_assert_eq!(
            (field.name, field.ty),
            (name, ty),
            "header field {} written out of the layout's order",
            self.next
        );
        self.next += 1;
        field
    }

    /// Writes the next field, `name`.
    pub(super) fn put<T: Number>(&mut self, name: &str, value: T) {
        let field = self.field(name, FieldType::Number(T::SCALAR));
        value.write_le(&mut self.buf[field.offset..]);
    }

    /// Writes the next fields, named `names`, one value each.
    pub(super) fn put_all<T: Number>(&mut self, names: &[&str], values: &[T]) {
        debug_assert_eq!(names.len(), values.len());
        for (name, &value) in names.iter().zip(values) {
            self.put(name, value);
        }
    }

    /// Writes the array table, the next field: each array's offset and length.
    pub(super) fn array_table(&mut self, table: &[(usize, usize); ARRAYS]) {
        let field = self.field("arrays", FieldType::ArrayTable);
        for (i, &(offset, len)) in table.iter().enumerate() {
            let at = field.offset + 16 * i;
            (offset as u64).write_le(&mut self.buf[at..]);
            (len as u64).write_le(&mut self.buf[at + 8..]);
        }
    }

    /// Ends the header; in debug builds, checks that every field was written.
    pub(super) fn finish(self) {
        debug_assert_eq!(
            self.next,
            self.fields.len(),
            "a header with fields left unwritten"
        );
    }
}

/// The offset of field `name` of `fields`, found when the program is compiled (a name the
/// table does not have does not compile).
pub(super) const fn offset_of(fields: &[Field], name: &str) -> usize {
    let mut i = 0;
    while i < fields.len() {
        if same(fields[i].name.as_bytes(), name.as_bytes()) {
            return fields[i].offset;
        }
        i += 1;
    }
    panic!("no field of this name in the layout");
}

/// Whether `a` and `b` are the same bytes (`==` on slices is not a `const fn`).
const fn same(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::super::{ANSWER_HEADER_BYTES, REQUEST_HEADER_BYTES};
    use super::*;
    use std::path::Path;

    /// The layout's tables and the size of what each describes.
    fn tables() -> [(&'static str, &'static [Field], usize); 4] {
        [
            ("the request header", REQUEST_FIELDS, REQUEST_HEADER_BYTES),
            ("the answer header", ANSWER_FIELDS, ANSWER_HEADER_BYTES),
            (
                "a targets row",
                TARGET_ROW_FIELDS,
                row_bytes(TARGET_ROW_FIELDS),
            ),
            (
                "an others row",
                OTHER_ROW_FIELDS,
                row_bytes(OTHER_ROW_FIELDS),
            ),
        ]
    }

    #[test]
    fn the_fields_follow_each_other_aligned_and_named_once() {
        for (what, fields, size) in tables() {
            let mut at = 0;
            for (i, f) in fields.iter().enumerate() {
                assert_eq!(
                    f.offset, at,
                    "{what}: {} does not follow the field before",
                    f.name
                );
                let align = match f.ty {
                    FieldType::Number(s) => s.bytes(),
                    FieldType::ArrayTable => 8,
                };
                assert_eq!(f.offset % align, 0, "{what}: {} is not aligned", f.name);
                assert!(
                    !fields[..i].iter().any(|g| g.name == f.name),
                    "{what}: {} twice",
                    f.name
                );
                if f.joined {
                    assert!(
                        i > 0 && fields[i - 1].ty == f.ty,
                        "{what}: {} joins another type",
                        f.name
                    );
                }
                at = f.end();
            }
            assert!(
                at <= size,
                "{what}: its fields end at {at}, past its {size} bytes"
            );
        }
        assert_eq!(row_bytes(ANSWER_FIELDS), ANSWER_HEADER_BYTES);
    }

    fn read(path: &str) -> String {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path);
        std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()))
    }

    /// The cells of each row of the Markdown table that starts at the first line after
    /// `after` that begins with `|`, without its heading and rule.
    fn markdown_table(doc: &str, after: &str) -> Vec<Vec<String>> {
        let at = doc
            .find(after)
            .unwrap_or_else(|| panic!("docs/python.md has no {after:?}"));
        doc[at..]
            .lines()
            .skip_while(|l| !l.starts_with('|'))
            .take_while(|l| l.starts_with('|'))
            .skip(2)
            .map(|l| {
                let cells = l.trim().trim_start_matches('|').trim_end_matches('|');
                cells.split('|').map(|c| c.trim().to_owned()).collect()
            })
            .collect()
    }

    /// The rows `docs/python.md` gives a header of `fields` and `size` bytes: offset, type
    /// and fields; a field joined to the one before shares its row.
    fn doc_rows(fields: &[Field], size: usize) -> Vec<[String; 3]> {
        let mut rows: Vec<(Field, Vec<&str>)> = Vec::new();
        for f in fields {
            match rows.last_mut() {
                Some((_, names)) if f.joined => names.push(f.name),
                _ => rows.push((*f, vec![f.name])),
            }
        }
        let mut text: Vec<[String; 3]> = rows
            .iter()
            .map(|(first, names)| {
                let ty = match first.ty {
                    FieldType::Number(s) if names.len() == 1 => s.name().to_owned(),
                    FieldType::Number(s) => format!("{} ×{}", s.name(), names.len()),
                    FieldType::ArrayTable => format!("(u64, u64) ×{ARRAYS}"),
                };
                let names: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
                [first.offset.to_string(), ty, names.join(", ")]
            })
            .collect();
        let end = row_bytes(fields);
        if end < size {
            text.push([end.to_string(), String::new(), String::new()]);
        }
        text
    }

    #[test]
    fn the_docs_tables_give_the_layout() {
        let doc = read("docs/python.md");
        for (what, heading, fields, size) in [
            (
                "request",
                "**Header**",
                REQUEST_FIELDS,
                REQUEST_HEADER_BYTES,
            ),
            (
                "answer",
                "## The answer",
                ANSWER_FIELDS,
                ANSWER_HEADER_BYTES,
            ),
        ] {
            let documented: Vec<[String; 3]> = markdown_table(&doc, heading)
                .into_iter()
                .filter(|r| r[0].parse::<usize>().is_ok_and(|o| o < size))
                .map(|r| [r[0].clone(), r[1].clone(), r[2].clone()])
                .collect();
            let expected = doc_rows(fields, size);
            for (i, row) in expected.iter().enumerate() {
                let got = documented.get(i);
                assert_eq!(
                    got,
                    Some(row),
                    "docs/python.md, the {what} header: row {} should be | {} |",
                    i + 1,
                    row.join(" | ")
                );
            }
            assert_eq!(
                documented.len(),
                expected.len(),
                "docs/python.md, the {what} header: rows past the layout"
            );
        }
        let arrays = markdown_table(&doc, "| # | name | dtype |");
        assert_eq!(arrays.len(), ARRAYS, "docs/python.md: the arrays' table");
        for (i, (row, array)) in arrays.iter().zip(&REQUEST_ARRAYS).enumerate() {
            let dtype = match array.element {
                Element::Number(s) => format!("`{}`", s.dtype()),
                Element::Row(_) => "struct".to_owned(),
            };
            let expected = [i.to_string(), format!("`{}`", array.name), dtype];
            assert_eq!(
                row[..3],
                expected,
                "docs/python.md: array {i}, {}",
                array.name
            );
            if let Element::Row(fields) = array.element {
                let cells: Vec<String> = fields
                    .iter()
                    .map(|f| match f.ty {
                        FieldType::Number(s) => format!("{} {}", f.name, s.dtype()),
                        FieldType::ArrayTable => unreachable!("a row holds numbers"),
                    })
                    .collect();
                let text = format!("`{}` ({} bytes)", cells.join(", "), row_bytes(fields));
                assert!(
                    row[4].contains(&text),
                    "docs/python.md: array {i}, {}: its row is {text}",
                    array.name
                );
            }
        }
    }

    /// A field as `layout.py`'s `_struct` lists it: `("name", "<u4", offset)`.
    fn python_field(f: &Field) -> String {
        let dtype = match f.ty {
            FieldType::Number(s) => format!("\"{}\"", s.dtype()),
            FieldType::ArrayTable => format!("(\"<u8\", ({ARRAYS}, 2))"),
        };
        format!("(\"{}\", {dtype}, {})", f.name, f.offset)
    }

    /// The top-level items of a Python tuple or list's inside, split at its commas.
    fn items(inside: &str) -> Vec<&str> {
        let (mut depth, mut start, mut out) = (0i32, 0, Vec::new());
        for (i, c) in inside.char_indices() {
            match c {
                '(' | '[' => depth += 1,
                ')' | ']' => depth -= 1,
                ',' if depth == 0 => {
                    out.push(inside[start..i].trim());
                    start = i + 1;
                }
                _ => {}
            }
        }
        out.push(inside[start..].trim());
        out.retain(|s| !s.is_empty());
        out
    }

    /// What is between the bracket that opens at `open` in `text` and the one that closes it.
    fn inside(text: &str, open: usize) -> &str {
        let mut depth = 0;
        for (i, c) in text[open..].char_indices() {
            match c {
                '(' | '[' => depth += 1,
                ')' | ']' => {
                    depth -= 1;
                    if depth == 0 {
                        return &text[open + 1..open + i];
                    }
                }
                _ => {}
            }
        }
        panic!("unclosed bracket in python/setfleet/layout.py");
    }

    /// The value of `NAME = value` in `py`.
    fn constant(py: &str, name: &str) -> u64 {
        let line = py
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{name} = ")))
            .unwrap_or_else(|| panic!("python/setfleet/layout.py has no {name}"));
        let value = match line.strip_prefix("0x") {
            Some(hex) => u64::from_str_radix(hex, 16),
            None => line.parse(),
        };
        value.unwrap_or_else(|e| panic!("python/setfleet/layout.py: {name} = {line}: {e}"))
    }

    #[test]
    fn the_python_dtypes_give_the_layout() {
        let py = read("python/setfleet/layout.py");
        for (name, fields, size) in [
            ("REQUEST_HEADER", REQUEST_FIELDS, REQUEST_HEADER_BYTES),
            ("ANSWER_HEADER", ANSWER_FIELDS, ANSWER_HEADER_BYTES),
            (
                "TARGET_ROW",
                TARGET_ROW_FIELDS,
                row_bytes(TARGET_ROW_FIELDS),
            ),
            ("OTHER_ROW", OTHER_ROW_FIELDS, row_bytes(OTHER_ROW_FIELDS)),
        ] {
            let start = py
                .find(&format!("\n{name}: np.dtype = _struct("))
                .unwrap_or_else(|| panic!("python/setfleet/layout.py has no {name}"));
            let open = start + py[start..].find('(').unwrap_or_default();
            let args = items(inside(&py, open));
            assert_eq!(
                args.len(),
                2,
                "python/setfleet/layout.py: {name} = _struct(fields, itemsize)"
            );
            let list = items(&args[0][1..args[0].len() - 1]);
            for (i, f) in fields.iter().enumerate() {
                let expected = python_field(f);
                let got = list
                    .get(i)
                    .map(|e| format!("({})", items(&e[1..e.len() - 1]).join(", ")));
                assert_eq!(
                    got.as_ref(),
                    Some(&expected),
                    "python/setfleet/layout.py: field {i} of {name} should be {expected}"
                );
            }
            assert_eq!(
                list.len(),
                fields.len(),
                "python/setfleet/layout.py: {name} has fields past the layout"
            );
            let itemsize = args[1].parse().unwrap_or_else(|_| constant(&py, args[1]));
            assert_eq!(
                itemsize, size as u64,
                "python/setfleet/layout.py: the size of {name}"
            );
        }
        use super::super::{
            ANSWER_MAGIC, FLAG_ROUND_START, LAYOUT_VERSION, MAX_ANSWER_INCREMENTS,
            MAX_ANSWER_POSES, REQUEST_MAGIC,
        };
        for (name, value) in [
            ("REQUEST_MAGIC", u64::from(REQUEST_MAGIC)),
            ("ANSWER_MAGIC", u64::from(ANSWER_MAGIC)),
            ("VERSION", u64::from(LAYOUT_VERSION)),
            ("REQUEST_HEADER_BYTES", REQUEST_HEADER_BYTES as u64),
            ("ANSWER_HEADER_BYTES", ANSWER_HEADER_BYTES as u64),
            ("MAX_ANSWER_INCREMENTS", u64::from(MAX_ANSWER_INCREMENTS)),
            ("MAX_ANSWER_VIEWS", u64::from(MAX_ANSWER_POSES)),
            ("FLAG_ROUND_START", u64::from(FLAG_ROUND_START)),
        ] {
            assert_eq!(
                constant(&py, name),
                value,
                "python/setfleet/layout.py: {name}"
            );
        }
        let start = py
            .find("\nARRAY_NAMES: tuple[str, ...] = (")
            .expect("ARRAY_NAMES");
        let open = start + py[start..].find('(').unwrap_or_default();
        let names: Vec<&str> = items(inside(&py, open))
            .iter()
            .map(|n| n.trim_matches('"'))
            .collect();
        let expected: Vec<&str> = REQUEST_ARRAYS.iter().map(|a| a.name).collect();
        assert_eq!(names, expected, "python/setfleet/layout.py: ARRAY_NAMES");
    }
}
