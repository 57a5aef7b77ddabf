//! [`enum_with_unknown!`](crate::enum_with_unknown): one table per code set.

/// Declare a code set of the standard as an enum whose every code value
/// decodes: the listed codes become variants, any other code
/// `Unknown(code)`, so decoding is total and re-encoding restores the
/// byte. Each code and its name are written once, in one table; the
/// conversions both ways and the name lookup are generated from it.
///
/// Generated for `enum Name(u8)`:
/// - `Name::from_code(u8) -> Name` and `Name::code(self) -> u8` (both
///   `const`), and `From` both ways;
/// - `Name::name(self) -> Option<&'static str>`: the listed name, `None`
///   for `Unknown`;
/// - `Debug`, `Clone`, `Copy`, `PartialEq`, `Eq`, `Hash`.
///
/// An optional `& MASK` after the type keeps only the code's bits in
/// `Unknown` (for a field that shares its byte with other fields).
///
/// ```
/// profibus_fdl::enum_with_unknown! {
///     /// Traffic lights.
///     pub enum Light(u8) {
///         /// Stop.
///         Red = 1 => "red",
///         /// Go.
///         Green = 3 => "green",
///     }
/// }
/// assert_eq!(Light::from_code(3), Light::Green);
/// assert_eq!(Light::from_code(7), Light::Unknown(7));
/// assert_eq!(Light::Unknown(7).code(), 7);
/// assert_eq!(Light::Red.name(), Some("red"));
/// assert_eq!(u8::from(Light::Green), 3);
/// ```
#[macro_export]
macro_rules! enum_with_unknown {
    (
        $(#[$attr:meta])*
        $vis:vis enum $name:ident($ty:ident $(& $mask:literal)?) {
            $(
                $(#[$vattr:meta])*
                $variant:ident = $code:literal => $text:literal
            ),+ $(,)?
        }
    ) => {
        $(#[$attr])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        $vis enum $name {
            $(
                $(#[$vattr])*
                $variant,
            )+
            /// Any other code, as received.
            Unknown($ty),
        }

        impl $name {
            /// Decode a code; every value maps to a variant.
            pub const fn from_code(code: $ty) -> Self {
                match code {
                    $( $code => Self::$variant, )+
                    other => Self::Unknown(other $(& $mask)?),
                }
            }

            /// The code of this variant.
            pub const fn code(self) -> $ty {
                match self {
                    $( Self::$variant => $code, )+
                    Self::Unknown(code) => code $(& $mask)?,
                }
            }

            /// The name the standard gives this code; `None` for
            /// `Unknown`.
            pub const fn name(self) -> ::core::option::Option<&'static str> {
                match self {
                    $( Self::$variant => ::core::option::Option::Some($text), )+
                    Self::Unknown(_) => ::core::option::Option::None,
                }
            }
        }

        impl ::core::convert::From<$ty> for $name {
            fn from(code: $ty) -> Self {
                Self::from_code(code)
            }
        }

        impl ::core::convert::From<$name> for $ty {
            fn from(value: $name) -> $ty {
                value.code()
            }
        }
    };
}
