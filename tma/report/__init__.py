"""What ``aggregate`` writes: tables (``tables``: CSV, Markdown, figures), each with its
section "Against the paper" (``paper``), formatted by ``markdown``."""
