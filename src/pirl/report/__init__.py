"""The reproduction report: tables, figures and sections, written as Markdown and HTML."""
