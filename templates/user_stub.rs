    {{ method.user_signature }} {
    {%- for line in method.stub_body %}
        {{ line }}
    {%- endfor %}
    }
