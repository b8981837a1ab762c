"""The plugin's setting, the csboundary command to run, read where Processing keeps its settings."""

COMMAND_SETTING = "CSBOUNDARY_COMMAND"


def configured_command() -> str:
    """The setting's value ('' when unset or when Processing's settings are not loaded)."""
    try:
        from processing.core.ProcessingConfig import ProcessingConfig
    except ImportError:
        return ""
    return str(ProcessingConfig.getSetting(COMMAND_SETTING) or "")
