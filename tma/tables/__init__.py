"""What ``aggregate`` writes: tables (``write``: CSV, Markdown, figures), each with its
section "Against the paper" (``paper``), formatted by ``markdown``."""
