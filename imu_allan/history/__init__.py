"""The analysis history: the DuckDB tables ``analyze --db`` fills and ``fleet`` reads."""
