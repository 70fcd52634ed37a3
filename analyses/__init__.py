"""Analysis scripts that turn the library into PDF reports (shipped as maglev_oc.analyses)."""
