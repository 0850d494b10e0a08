"""Importers of third-party flight logs into telemetry files and a post2 problem file
(``workbench import <format> ...``; :data:`workbench.problems.registry.IMPORTERS`)."""
