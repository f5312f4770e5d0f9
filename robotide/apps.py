from django.apps import AppConfig


class RobotideConfig(AppConfig):
    name = "robotide"
    verbose_name = "robotide"
