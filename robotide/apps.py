from django.apps import AppConfig


class RobotideConfig(AppConfig):
    name = "robotide"
    verbose_name = "robotide"

    def ready(self):
        from django.contrib.auth.signals import user_logged_in

        from robotide import security  # noqa: F401  (counts failed sign-ins)
        from robotide.language import remember_on_sign_in

        user_logged_in.connect(remember_on_sign_in, dispatch_uid="robotide-language")
