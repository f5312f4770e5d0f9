from django.apps import AppConfig


class RobotideConfig(AppConfig):
    name = "robotide"
    verbose_name = "robotide"

    def ready(self):
        from robotide import security  # noqa: F401  (counts failed sign-ins)
