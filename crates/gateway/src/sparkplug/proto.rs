//! The Sparkplug B payload messages as `prost` structs, written by hand
//! to match `proto/sparkplug_b.proto` field for field (names, numbers,
//! types; proto2 `optional` fields are `Option`s). Deriving
//! [`prost::Message`] on them needs no protoc and no build script; the
//! tests check the wire format against the `.proto` with `protoc`.

/// A `oneof` of the schema's values: the six scalar kinds every value
/// `oneof` has (integer, long, float, double, boolean, string) at the
/// given tags, then the variants of its own.
macro_rules! value_oneof {
    (
        $(#[$doc:meta])*
        $name:ident { $int:tt, $long:tt, $float:tt, $double:tt, $bool:tt, $string:tt }
        $($own:tt)*
    ) => {
        $(#[$doc])*
        #[derive(Clone, PartialEq, prost::Oneof)]
        pub enum $name {
            /// Int8..Int32 (two's complement), UInt8..UInt32.
            #[prost(uint32, tag = $int)]
            IntValue(u32),
            /// Int64 (two's complement), UInt64, DateTime.
            #[prost(uint64, tag = $long)]
            LongValue(u64),
            /// Float.
            #[prost(float, tag = $float)]
            FloatValue(f32),
            /// Double.
            #[prost(double, tag = $double)]
            DoubleValue(f64),
            /// Boolean.
            #[prost(bool, tag = $bool)]
            BooleanValue(bool),
            /// String, Text, UUID.
            #[prost(string, tag = $string)]
            StringValue(String),
            $($own)*
        }
    };
}

/// One Sparkplug message: NBIRTH, DDATA, DCMD, ….
#[derive(Clone, PartialEq, prost::Message)]
pub struct Payload {
    /// When the message was sent, ms since the Unix epoch (UTC).
    #[prost(uint64, optional, tag = "1")]
    pub timestamp: Option<u64>,
    /// The metrics.
    #[prost(message, repeated, tag = "2")]
    pub metrics: Vec<Metric>,
    /// Sequence number 0..=255 (not in NDEATH, NCMD, DCMD).
    #[prost(uint64, optional, tag = "3")]
    pub seq: Option<u64>,
    /// Schema identifier.
    #[prost(string, optional, tag = "4")]
    pub uuid: Option<String>,
    /// Opaque body.
    #[prost(bytes = "vec", optional, tag = "5")]
    pub body: Option<Vec<u8>>,
}

/// One value of a payload (a tag, in SCADA terms).
#[derive(Clone, PartialEq, prost::Message)]
pub struct Metric {
    /// Name; `/` separates folders (`Node Control/Rebirth`).
    #[prost(string, optional, tag = "1")]
    pub name: Option<String>,
    /// Alias (not used by this gateway).
    #[prost(uint64, optional, tag = "2")]
    pub alias: Option<u64>,
    /// When the value was taken, ms since the Unix epoch (UTC).
    #[prost(uint64, optional, tag = "3")]
    pub timestamp: Option<u64>,
    /// A [`DataType`] code.
    #[prost(uint32, optional, tag = "4")]
    pub datatype: Option<u32>,
    /// Historical data, not the current value.
    #[prost(bool, optional, tag = "5")]
    pub is_historical: Option<bool>,
    /// Not to be stored as a tag by hosts.
    #[prost(bool, optional, tag = "6")]
    pub is_transient: Option<bool>,
    /// The value is null.
    #[prost(bool, optional, tag = "7")]
    pub is_null: Option<bool>,
    /// Metadata.
    #[prost(message, optional, tag = "8")]
    pub metadata: Option<MetaData>,
    /// Properties.
    #[prost(message, optional, tag = "9")]
    pub properties: Option<PropertySet>,
    /// The value.
    #[prost(oneof = "MetricValue", tags = "10, 11, 12, 13, 14, 15, 16, 17, 18, 19")]
    pub value: Option<MetricValue>,
}

value_oneof! {
    /// The value of a [`Metric`].
    MetricValue { "10", "11", "12", "13", "14", "15" }
    /// Bytes, File, arrays.
    #[prost(bytes = "vec", tag = "16")]
    BytesValue(Vec<u8>),
    /// DataSet.
    #[prost(message, tag = "17")]
    DatasetValue(DataSet),
    /// Template.
    #[prost(message, tag = "18")]
    TemplateValue(Template),
    /// Extension.
    #[prost(message, tag = "19")]
    ExtensionValue(Extension),
}

/// An extension value (no fields of its own).
#[derive(Clone, PartialEq, prost::Message)]
pub struct Extension {}

/// Metadata of a metric (files, multi-part bytes).
#[derive(Clone, PartialEq, prost::Message)]
pub struct MetaData {
    /// Part of a multi-part value.
    #[prost(bool, optional, tag = "1")]
    pub is_multi_part: Option<bool>,
    /// Media type.
    #[prost(string, optional, tag = "2")]
    pub content_type: Option<String>,
    /// Size in bytes.
    #[prost(uint64, optional, tag = "3")]
    pub size: Option<u64>,
    /// Part number.
    #[prost(uint64, optional, tag = "4")]
    pub seq: Option<u64>,
    /// File name.
    #[prost(string, optional, tag = "5")]
    pub file_name: Option<String>,
    /// File type.
    #[prost(string, optional, tag = "6")]
    pub file_type: Option<String>,
    /// MD5 of the data.
    #[prost(string, optional, tag = "7")]
    pub md5: Option<String>,
    /// Free text.
    #[prost(string, optional, tag = "8")]
    pub description: Option<String>,
}

/// Properties: `keys[i]` has `values[i]`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PropertySet {
    /// Property names.
    #[prost(string, repeated, tag = "1")]
    pub keys: Vec<String>,
    /// Property values.
    #[prost(message, repeated, tag = "2")]
    pub values: Vec<PropertyValue>,
}

/// A list of property sets.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PropertySetList {
    /// The sets.
    #[prost(message, repeated, tag = "1")]
    pub propertyset: Vec<PropertySet>,
}

/// One property's value.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PropertyValue {
    /// A [`DataType`] code.
    #[prost(uint32, optional, tag = "1")]
    pub r#type: Option<u32>,
    /// The value is null.
    #[prost(bool, optional, tag = "2")]
    pub is_null: Option<bool>,
    /// The value.
    #[prost(oneof = "PropertyValueValue", tags = "3, 4, 5, 6, 7, 8, 9, 10, 11")]
    pub value: Option<PropertyValueValue>,
}

value_oneof! {
    /// The value of a [`PropertyValue`].
    PropertyValueValue { "3", "4", "5", "6", "7", "8" }
    /// PropertySet.
    #[prost(message, tag = "9")]
    PropertysetValue(PropertySet),
    /// PropertySetList.
    #[prost(message, tag = "10")]
    PropertysetsValue(PropertySetList),
    /// Extension.
    #[prost(message, tag = "11")]
    ExtensionValue(Extension),
}

/// A table.
#[derive(Clone, PartialEq, prost::Message)]
pub struct DataSet {
    /// Number of columns.
    #[prost(uint64, optional, tag = "1")]
    pub num_of_columns: Option<u64>,
    /// Column names.
    #[prost(string, repeated, tag = "2")]
    pub columns: Vec<String>,
    /// Column [`DataType`] codes.
    #[prost(uint32, repeated, packed = "false", tag = "3")]
    pub types: Vec<u32>,
    /// Rows.
    #[prost(message, repeated, tag = "4")]
    pub rows: Vec<Row>,
}

/// One row of a [`DataSet`].
#[derive(Clone, PartialEq, prost::Message)]
pub struct Row {
    /// One value per column.
    #[prost(message, repeated, tag = "1")]
    pub elements: Vec<DataSetValue>,
}

/// One cell of a [`DataSet`].
#[derive(Clone, PartialEq, prost::Message)]
pub struct DataSetValue {
    /// The value.
    #[prost(oneof = "DataSetValueValue", tags = "1, 2, 3, 4, 5, 6, 7")]
    pub value: Option<DataSetValueValue>,
}

value_oneof! {
    /// The value of a [`DataSetValue`].
    DataSetValueValue { "1", "2", "3", "4", "5", "6" }
    /// Extension.
    #[prost(message, tag = "7")]
    ExtensionValue(Extension),
}

/// A user-defined type: a definition or an instance.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Template {
    /// Version of the definition.
    #[prost(string, optional, tag = "1")]
    pub version: Option<String>,
    /// Members.
    #[prost(message, repeated, tag = "2")]
    pub metrics: Vec<Metric>,
    /// Parameters.
    #[prost(message, repeated, tag = "3")]
    pub parameters: Vec<Parameter>,
    /// The definition an instance is of.
    #[prost(string, optional, tag = "4")]
    pub template_ref: Option<String>,
    /// A definition, not an instance.
    #[prost(bool, optional, tag = "5")]
    pub is_definition: Option<bool>,
}

/// A parameter of a [`Template`].
#[derive(Clone, PartialEq, prost::Message)]
pub struct Parameter {
    /// Name.
    #[prost(string, optional, tag = "1")]
    pub name: Option<String>,
    /// A [`DataType`] code.
    #[prost(uint32, optional, tag = "2")]
    pub r#type: Option<u32>,
    /// The value.
    #[prost(oneof = "ParameterValue", tags = "3, 4, 5, 6, 7, 8, 9")]
    pub value: Option<ParameterValue>,
}

value_oneof! {
    /// The value of a [`Parameter`].
    ParameterValue { "3", "4", "5", "6", "7", "8" }
    /// Extension.
    #[prost(message, tag = "9")]
    ExtensionValue(Extension),
}

/// The Sparkplug data types (the `DataType` enum of the schema): the
/// codes in [`Metric::datatype`] and friends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
#[allow(missing_docs)]
pub enum DataType {
    Unknown = 0,
    Int8 = 1,
    Int16 = 2,
    Int32 = 3,
    Int64 = 4,
    UInt8 = 5,
    UInt16 = 6,
    UInt32 = 7,
    UInt64 = 8,
    Float = 9,
    Double = 10,
    Boolean = 11,
    String = 12,
    DateTime = 13,
    Text = 14,
    Uuid = 15,
    DataSet = 16,
    Bytes = 17,
    File = 18,
    Template = 19,
    PropertySet = 20,
    PropertySetList = 21,
    Int8Array = 22,
    Int16Array = 23,
    Int32Array = 24,
    Int64Array = 25,
    UInt8Array = 26,
    UInt16Array = 27,
    UInt32Array = 28,
    UInt64Array = 29,
    FloatArray = 30,
    DoubleArray = 31,
    BooleanArray = 32,
    StringArray = 33,
    DateTimeArray = 34,
}

impl DataType {
    /// The code on the wire.
    pub fn code(self) -> u32 {
        self as u32
    }
}
