"""``ffd schema``: the JSON Schema of the design file (for editor validation)."""

from __future__ import annotations

import json

from ffdcli.cli import cli, common_options


@cli.command("schema")
@common_options
def schema_cmd(console):
    """Print the JSON Schema (draft 2020-12) of the design file.

    \b
    Save it and point your editor's YAML plugin at it, e.g. for VS Code:
      ffd schema > ffd-design.schema.json
      # yaml-language-server: $schema=ffd-design.schema.json   (first line of a design file)
    """
    from ffdcli.design import design_schema

    schema = design_schema()
    console.result(schema, json.dumps(schema, indent=2))
