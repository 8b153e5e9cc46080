{%- import "macros.rs" as m -%}
{% call m::header(krate.header()) %}{% endcall %}
//! Packets, enums, extern packets and converters of the descriptions.
{% for e in types.externs %}


{% call m::doc(&e.doc) %}{% endcall %}
pub type {{ e.name }} = {{ e.path }};
{% endfor %}
{%- for p in types.packets %}


{% call m::doc(&p.doc) %}{% endcall %}
{% call m::packet(p) %}{% endcall %})]
pub struct {{ p.name }} {
{%- for f in p.fields %}
{%- call m::doc(&f.doc) %}{% endcall %}
    {%- if f.renamed() %}
    #[serde(rename = "{{ f.cool_name }}")]
    {%- endif %}
    {%- if let Some(adapter) = f.serde_with %}
    #[serde(with = "{{ adapter }}")]
    {%- endif %}
    pub {{ f.name }}: {{ f.ty }},
{%- endfor %}
}
{% if p.writes_default() %}
impl ::core::default::Default for {{ p.name }} {
    fn default() -> Self {
        Self {
        {%- for f in p.fields %}
            {{ f.name }}: {{ f.default }},
        {%- endfor %}
        }
    }
}
{% endif %}
{%- endfor %}
{%- for e in types.enums %}


{% call m::doc(&e.doc) %}{% endcall %}
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, ::serde::Serialize, ::serde::Deserialize{% if !e.variants.is_empty() %}, Default{% endif %})]
pub enum {{ e.name }} {
{%- for v in e.variants %}
{%- call m::doc(&v.doc) %}{% endcall %}
    {%- if loop.first %}
    #[default]
    {%- endif %}
    {%- if v.name != v.cool_name %}
    #[serde(rename = "{{ v.cool_name }}")]
    {%- endif %}
    {{ v.name }},
{%- endfor %}
}
{%- endfor %}
{% if !types.converters.is_empty() %}
/// The converters of the descriptions: implement this trait in `src/converters.rs`.
///
/// A connection declared `via` a converter calls its method on every packet.
pub trait Converters {
{%- for c in types.converters %}
{%- call m::doc(&c.doc) %}{% endcall %}
    /// Converter `{{ c.cool_name }}`.
    fn {{ c.method }}(from: &{{ c.from }}) -> {{ c.to }};
{%- endfor %}
}
{% endif %}
{%- if !types.ros.is_empty() %}


/// The ROS 2 message types the descriptions import (`import ros`) and every type
/// they reference, one module per package; the types module names each imported one.
#[allow(
    clippy::approx_constant,
    reason = "constants and defaults are the values the `.msg` files write"
)]
pub mod ros {
{%- for package in types.ros %}
{%- if !loop.first %}
{% endif %}
    /// The ROS 2 package `{{ package.package }}`.
    pub mod {{ package.module }} {
    {%- for message in package.messages %}
    {%- let p = message.packet %}
    {%- if !loop.first %}
{% endif %}
{%- call m::doc(&p.doc) %}{% endcall %}
{% call m::packet(p) %}{% endcall %})]
pub struct {{ p.name }} {
{%- for f in p.fields %}
{%- call m::doc(&f.doc) %}{% endcall %}
    {%- if f.renamed() %}
    #[serde(rename = "{{ f.cool_name }}")]
    {%- endif %}
    {%- if let Some(adapter) = f.serde_with %}
    #[serde(with = "{{ adapter }}")]
    {%- endif %}
    pub {{ f.name }}: {{ f.ty }},
{%- endfor %}
}
{% if p.writes_default() %}
impl ::core::default::Default for {{ p.name }} {
    fn default() -> Self {
        Self {
        {%- for f in p.fields %}
            {{ f.name }}: {{ f.default }},
        {%- endfor %}
        }
    }
}
{% endif %}
{%- if !message.constants.is_empty() %}
impl {{ p.name }} {
{%- for c in message.constants %}
{%- call m::doc(&c.doc) %}{% endcall %}
    pub const {{ c.name }}: {{ c.ty }} = {{ c.value }};
{%- endfor %}
}
{% endif %}
impl ::coolbot::ros::RosType for {{ p.name }} {
    const NAME: &'static str = {{ message.name }};
    const DDS_NAME: &'static str = {{ message.dds_name }};
    const TYPE_HASH: &'static str = {{ message.hash }};
    const MESSAGE_DEFINITION: &'static str = {{ message.definition }};
}
    {%- endfor %}
    }
{%- endfor %}
}
{%- endif %}
