# Drops the `*_is_in_phys_range(double value)` checks (with their doc comments) that
# `cantools generate_c_source --no-floating-point-numbers` (45.x) still emits: the port has no
# floating point at all. Everything else of the generated code passes through unchanged.
/^\/\*\*/ && !in_comment { comment = $0 "\n"; in_comment = 1; next }
in_comment {
    comment = comment $0 "\n"
    if ($0 ~ /\*\/$/) { in_comment = 0; pending = 1 }
    next
}
pending {
    pending = 0
    if ($0 ~ /_is_in_phys_range\(double value\);$/) { comment = ""; skip_blank = 1; next }
    printf "%s", comment
    comment = ""
}
/_is_in_phys_range\(double value\)$/ { in_function = 1; next }
in_function { if ($0 == "}") { in_function = 0; skip_blank = 1 }; next }
skip_blank && $0 == "" { skip_blank = 0; next }
{ skip_blank = 0; print }
