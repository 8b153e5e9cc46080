{%- import "macros.rs" as m -%}
{% call m::header(krate.header()) %}{% endcall %}
//! Links the native libraries the descriptions name with `link system`.

fn main() {
{%- for lib in krate.system_libs %}
    println!("cargo:rustc-link-lib={{ lib }}");
{%- endfor %}
}
