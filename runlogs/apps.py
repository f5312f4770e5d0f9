from django.apps import AppConfig
from django.utils.translation import gettext_lazy as _


class RunLogsConfig(AppConfig):
    name = "runlogs"
    verbose_name = _("Run logs")
