//! A value as a Rust expression, through its serde form: the tables of a coefficient set
//! become a const initialiser without `Debug` output, whose text no release promises.
//!
//! Structs become `Name { field: value }`, fixed-size arrays (serde's tuples) `[a, b]`, unit
//! variants `Enum::Variant`, integers their decimal and floats the shortest decimal that reads
//! back to the same bits (ryu, Adams, PLDI 2018), so a generated const equals its source bit
//! for bit. Whatever a const cannot hold (strings, sequences, maps, options) is refused.

use std::fmt::Display;

use serde::Serialize;
use serde::ser::{self, Impossible};

/// Why a value has no Rust literal.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct LiteralError(String);

impl ser::Error for LiteralError {
    fn custom<T: Display>(message: T) -> Self {
        Self(message.to_string())
    }
}

/// `value` as a Rust expression.
pub fn to_rust(value: &impl Serialize) -> Result<String, LiteralError> {
    value.serialize(Literal)
}

/// The shortest decimal that reads back to `value`'s bits, as a float literal (`1.0`, `-2.5e-7`).
#[must_use]
pub fn f32_literal(value: f32) -> String {
    ryu::Buffer::new().format(value).to_owned()
}

fn refused(what: &str) -> LiteralError {
    LiteralError(format!("a {what} has no const literal in the generated tables"))
}

/// The serializer: every call returns the expression of what it was given.
struct Literal;

/// The items of a compound value, joined when it ends.
struct Items {
    /// Text before the items (`Name { `, `[`, `Name(`).
    open: String,
    /// Text after them.
    close: &'static str,
    items: Vec<String>,
}

impl Items {
    fn new(open: String, close: &'static str) -> Self {
        Self { open, close, items: Vec::new() }
    }

    fn push(&mut self, value: &(impl Serialize + ?Sized), field: Option<&str>) -> Result<(), LiteralError> {
        let value = value.serialize(Literal)?;
        self.items.push(match field {
            Some(field) => format!("{field}: {value}"),
            None => value,
        });
        Ok(())
    }

    fn finish(self) -> String {
        format!("{}{}{}", self.open, self.items.join(", "), self.close)
    }
}

impl ser::Serializer for Literal {
    type Ok = String;
    type Error = LiteralError;
    type SerializeSeq = Impossible<String, LiteralError>;
    type SerializeTuple = Items;
    type SerializeTupleStruct = Items;
    type SerializeTupleVariant = Items;
    type SerializeMap = Impossible<String, LiteralError>;
    type SerializeStruct = Items;
    type SerializeStructVariant = Items;

    fn serialize_bool(self, v: bool) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_i8(self, v: i8) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_i16(self, v: i16) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_i32(self, v: i32) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_i64(self, v: i64) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_u8(self, v: u8) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_u16(self, v: u16) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_u32(self, v: u32) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_u64(self, v: u64) -> Result<String, LiteralError> {
        Ok(v.to_string())
    }
    fn serialize_f32(self, v: f32) -> Result<String, LiteralError> {
        if v.is_finite() { Ok(f32_literal(v)) } else { Err(LiteralError(format!("{v} is not a finite number"))) }
    }
    fn serialize_f64(self, v: f64) -> Result<String, LiteralError> {
        if v.is_finite() {
            Ok(ryu::Buffer::new().format(v).to_owned())
        } else {
            Err(LiteralError(format!("{v} is not a finite number")))
        }
    }
    fn serialize_char(self, _: char) -> Result<String, LiteralError> {
        Err(refused("character"))
    }
    fn serialize_str(self, _: &str) -> Result<String, LiteralError> {
        Err(refused("string"))
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<String, LiteralError> {
        Err(refused("byte string"))
    }
    fn serialize_none(self) -> Result<String, LiteralError> {
        Err(refused("option"))
    }
    fn serialize_some<T: Serialize + ?Sized>(self, _: &T) -> Result<String, LiteralError> {
        Err(refused("option"))
    }
    fn serialize_unit(self) -> Result<String, LiteralError> {
        Ok("()".into())
    }
    fn serialize_unit_struct(self, name: &'static str) -> Result<String, LiteralError> {
        Ok(name.into())
    }
    fn serialize_unit_variant(self, name: &'static str, _: u32, variant: &'static str) -> Result<String, LiteralError> {
        Ok(format!("{name}::{variant}"))
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        name: &'static str,
        value: &T,
    ) -> Result<String, LiteralError> {
        Ok(format!("{name}({})", value.serialize(Literal)?))
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        name: &'static str,
        _: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<String, LiteralError> {
        Ok(format!("{name}::{variant}({})", value.serialize(Literal)?))
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Self::SerializeSeq, LiteralError> {
        Err(refused("sequence of run-time length"))
    }
    /// Fixed-size arrays reach serde as tuples; the coefficient set holds no Rust tuples.
    fn serialize_tuple(self, _: usize) -> Result<Items, LiteralError> {
        Ok(Items::new("[".into(), "]"))
    }
    fn serialize_tuple_struct(self, name: &'static str, _: usize) -> Result<Items, LiteralError> {
        Ok(Items::new(format!("{name}("), ")"))
    }
    fn serialize_tuple_variant(
        self,
        name: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Items, LiteralError> {
        Ok(Items::new(format!("{name}::{variant}("), ")"))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self::SerializeMap, LiteralError> {
        Err(refused("map"))
    }
    fn serialize_struct(self, name: &'static str, _: usize) -> Result<Items, LiteralError> {
        Ok(Items::new(format!("{name} {{ "), " }"))
    }
    fn serialize_struct_variant(
        self,
        name: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Items, LiteralError> {
        Ok(Items::new(format!("{name}::{variant} {{ "), " }"))
    }
}

/// The five compound traits differ only in their method's name and whether it gets a field
/// name; each pushes the item and joins the items at the end.
macro_rules! compound {
    ($trait:ident, $method:ident) => {
        impl ser::$trait for Items {
            type Ok = String;
            type Error = LiteralError;
            fn $method<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), LiteralError> {
                self.push(value, None)
            }
            fn end(self) -> Result<String, LiteralError> {
                Ok(self.finish())
            }
        }
    };
    ($trait:ident, $method:ident, keyed) => {
        impl ser::$trait for Items {
            type Ok = String;
            type Error = LiteralError;
            fn $method<T: Serialize + ?Sized>(&mut self, key: &'static str, value: &T) -> Result<(), LiteralError> {
                self.push(value, Some(key))
            }
            fn end(self) -> Result<String, LiteralError> {
                Ok(self.finish())
            }
        }
    };
}

compound!(SerializeTuple, serialize_element);
compound!(SerializeTupleStruct, serialize_field);
compound!(SerializeTupleVariant, serialize_field);
compound!(SerializeStruct, serialize_field, keyed);
compound!(SerializeStructVariant, serialize_field, keyed);

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct Inner {
        gain: f32,
        steps: u8,
    }

    #[derive(Serialize)]
    enum Factor {
        Var0,
    }

    #[derive(Serialize)]
    struct Outer {
        inner: [Inner; 2],
        factor: Factor,
        tiny: f32,
    }

    /// Structs, arrays, variants and floats become the Rust expression that builds them.
    #[test]
    fn a_struct_of_arrays_and_variants_becomes_its_rust_expression() {
        let value = Outer {
            inner: [Inner { gain: 0.5, steps: 4 }, Inner { gain: -1.0, steps: 0 }],
            factor: Factor::Var0,
            tiny: 1.427_876e-17,
        };
        assert_eq!(
            to_rust(&value).unwrap(),
            "Outer { inner: [Inner { gain: 0.5, steps: 4 }, Inner { gain: -1.0, steps: 0 }], \
             factor: Factor::Var0, tiny: 1.427876e-17 }"
        );
    }

    /// Every float literal reads back to the same bits, the signed zero and the extremes too.
    #[test]
    fn float_literals_read_back_bit_for_bit() {
        for value in [0.0f32, -0.0, 0.664_708_26, f32::MIN_POSITIVE, f32::MAX, -1.0e-45, 657.2904] {
            let text = f32_literal(value);
            assert_eq!(text.parse::<f32>().unwrap().to_bits(), value.to_bits(), "{text}");
        }
    }

    /// What a const cannot hold is refused, not written as something else.
    #[test]
    fn strings_options_and_non_finite_numbers_are_refused() {
        assert!(to_rust(&"text").is_err());
        assert!(to_rust(&Some(1u8)).is_err());
        assert!(to_rust(&vec![1u8]).is_err());
        assert!(to_rust(&f32::NAN).is_err());
    }
}
