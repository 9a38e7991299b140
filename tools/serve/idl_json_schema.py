#!/usr/bin/env python3
"""Generates the field tables of `pvcgel serve`'s JSON schemas from the IDL.

Run by CMake at build time: pvcgel_v1.idl -> a header with one table per
struct (name, JSON schema type, the field's IDL comment), so the schemas the
live view advertises follow the IDL the daemon is built from, field by field.
"""
import re
import sys

STRUCTS = ["Telemetry", "Status", "CommandReply"]
FIELD = re.compile(r"^\s*(?:@key\s+)?([a-z][a-z ]*?(?:<\d+>)?)\s+(\w+)(\[\d+\])?;\s*(?://\s*(.*))?$")


def json_type(idl_type, is_array):
    if is_array:
        return "array"
    if idl_type.startswith("string"):
        return "string"
    if idl_type in ("double", "float"):
        return "number|null"  # NaN (a faulted sensor) is encoded as null
    if idl_type == "boolean":
        return "boolean"
    if idl_type in ("octet", "short", "unsigned short", "long", "unsigned long", "long long", "unsigned long long"):
        return "integer"
    raise SystemExit(f"idl_json_schema.py: no JSON type for IDL type '{idl_type}'")


def fields(idl, struct):
    m = re.search(r"struct " + struct + r" \{(.*?)\};", idl, re.S)
    if not m:
        raise SystemExit(f"idl_json_schema.py: struct {struct} not found in the IDL")
    out = []
    for line in m.group(1).splitlines():
        f = FIELD.match(line)
        if not f:
            if line.strip() and not line.strip().startswith("//"):
                raise SystemExit(f"idl_json_schema.py: cannot read the {struct} line '{line.strip()}'")
            continue
        idl_type, name, array, comment = f.groups()
        description = (comment or f"{struct}.{name} (pvcgel_v1.idl)").replace("\\", "\\\\").replace('"', '\\"')
        out.append((name, json_type(idl_type, array is not None), description))
    return out


def main(idl_path, header_path):
    with open(idl_path, encoding="utf-8") as f:
        idl = f.read()
    lines = [
        "// Generated at build time by tools/serve/idl_json_schema.py from daemon/dds/pvcgel_v1.idl: do not edit.",
        "#pragma once",
        "",
        "namespace pvcgel::tools::serve::idl {",
        "",
        "/// One IDL field: its name, its JSON schema type (\"number|null\": NaN is null), its IDL comment.",
        "struct Field {",
        "  const char* name;",
        "  const char* type;",
        "  const char* description;",
        "};",
    ]
    for struct in STRUCTS:
        lines.append("")
        lines.append(f"inline constexpr Field k{struct}[] = {{")
        lines += [f'    {{"{n}", "{t}", "{d}"}},' for n, t, d in fields(idl, struct)]
        lines.append("};")
    lines += ["", "}  // namespace pvcgel::tools::serve::idl", ""]
    with open(header_path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
