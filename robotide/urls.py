from django.contrib import admin
from django.contrib.auth import views as auth_views
from django.urls import include, path
from django.utils import timezone
from django.views.decorators.http import last_modified
from django.views.generic import RedirectView
from django.views.i18n import JavaScriptCatalog

from programs import api_help, views_debug, workbench
from programs import views as programs
from robotide import language, oidc, views_health, views_icon
from robotide import views_account as account
from robotide.api import api
from robotide.security import LoginForm
from robots import gateway_views
from robots import reset as robot_reset
from robots import say as robot_say
from robots import views as robots

STARTED = timezone.now().replace(microsecond=0)  # the script catalog is as old as the process

urlpatterns = [
    path("", RedirectView.as_view(pattern_name="program-list"), name="home"),
    path("healthz", views_health.healthz, name="healthz"),
    # Pages name their icon; what asks for the old default (the admin, API docs, feeds) gets it.
    path("favicon.ico", views_icon.favicon, name="favicon"),
    path("programs/", programs.program_list, name="program-list"),
    path("programs/new", programs.program_create, name="program-create"),
    path("programs/upload", programs.program_upload, name="program-upload"),
    path("programs/export", programs.program_export, name="program-export"),
    path("programs/import", programs.program_import, name="program-import"),
    path("programs/<int:program_id>/", programs.program_edit, name="program-edit"),
    path("programs/<int:program_id>/run", programs.program_run, name="program-run"),
    path("programs/<int:program_id>/save", workbench.program_save, name="program-save"),
    path("programs/<int:program_id>/start", workbench.program_start, name="program-start"),
    path("programs/<int:program_id>/panel", workbench.program_panel, name="program-panel"),
    path("programs/<int:program_id>/draft", workbench.program_draft, name="program-draft"),
    path(
        "programs/<int:program_id>/blocks/python",
        workbench.blocks_python,
        name="program-blocks-python",
    ),
    path(
        "programs/<int:program_id>/blocks/as-python",
        workbench.blocks_as_python,
        name="program-blocks-as-python",
    ),
    path("programs/<int:program_id>/download", programs.program_download, name="program-download"),
    path("programs/<int:program_id>/delete", programs.program_delete, name="program-delete"),
    path("programs/<int:program_id>/email", programs.program_email, name="program-email"),
    path("programs/<int:program_id>/push", programs.program_push, name="program-push"),
    path("programs/<int:program_id>/revisions/", programs.revision_list, name="revision-list"),
    path(
        "programs/<int:program_id>/revisions/<int:number>/",
        programs.revision_detail,
        name="revision-detail",
    ),
    path("programs/<int:program_id>/shares/", programs.program_share, name="program-share"),
    path(
        "programs/<int:program_id>/shares/<int:share_id>/delete",
        programs.program_unshare,
        name="program-unshare",
    ),
    path("worlds/", include("worlds.urls")),
    # The classroom (issue 31): teachers' classes and exercises, students' exercises
    path("", include("classroom.urls_classes")),
    path("", include("classroom.urls_exercises")),
    path("", include("classroom.urls_student")),
    path("languages/", programs.language_list, name="language-list"),
    path("help/robot-api/", api_help.robot_api_page, name="robot-api-page"),
    path("help/robot-api/<slug:language>.json", api_help.robot_api_help, name="robot-api-help"),
    path("pages/", include("django.contrib.flatpages.urls")),
    path("runs/", programs.run_list, name="run-list"),
    path("runs/<int:run_id>/", programs.run_detail, name="run-detail"),
    path("runs/<int:run_id>/robot", programs.run_robot, name="run-robot"),
    path("runs/<int:run_id>/log", programs.run_log, name="run-log"),
    path("runs/<int:run_id>/stop", programs.run_stop, name="run-stop"),
    path("runs/<int:run_id>/debug", views_debug.run_debug, name="run-debug"),
    path("robots/", robots.robot_list, name="robot-list"),
    path("robots/<slug:name>/", robots.robot_detail, name="robot-detail"),
    path("robots/<slug:name>/settings", robots.robot_settings, name="robot-settings"),
    path("robots/<slug:name>/buttons/", robots.robot_buttons, name="robot-buttons"),
    path(
        "robots/<slug:name>/buttons/<int:button_id>/delete",
        robots.robot_button_delete,
        name="robot-button-delete",
    ),
    path(
        "robots/<slug:name>/buttons/<int:button_id>/press",
        robots.robot_button_press,
        name="robot-button-press",
    ),
    path("robots/<slug:name>/estop", robots.robot_estop, name="robot-estop"),
    path("robots/<slug:name>/resume", robots.robot_resume, name="robot-resume"),
    path("robots/<slug:name>/run", robots.robot_run, name="robot-run"),
    path("robots/<slug:name>/queue", robots.robot_queue, name="robot-queue"),
    path("robots/<slug:name>/queue/move", robots.robot_queue_move, name="robot-queue-move"),
    path("robots/<slug:name>/queue/resume", robots.robot_queue_resume, name="robot-queue-resume"),
    path("robots/<slug:name>/say", robot_say.robot_say, name="robot-say"),
    path("robots/<slug:name>/reset", robot_reset.robot_reset, name="robot-reset"),
    path("robots/<slug:name>/camera.jpg", robots.robot_camera, name="robot-camera"),
    path("robots/<slug:name>/world.json", robots.robot_world, name="robot-world"),
    path("robots/<slug:name>/gateway", gateway_views.robot_gateway, name="robot-gateway"),
    path(
        "robots/<slug:name>/gateway/endpoints",
        gateway_views.robot_endpoint_add,
        name="robot-endpoint-add",
    ),
    path(
        "robots/<slug:name>/gateway/endpoints/<int:endpoint_id>/delete",
        gateway_views.robot_endpoint_delete,
        name="robot-endpoint-delete",
    ),
    path(
        "accounts/login/",
        auth_views.LoginView.as_view(authentication_form=LoginForm),
        name="login",
    ),
    path("accounts/", account.account, name="account"),
    path(
        "accounts/tokens/<int:token_id>/revoke",
        account.token_revoke,
        name="account-token-revoke",
    ),
    path("accounts/logout/", oidc.SignOutView.as_view(), name="logout"),
    path("accounts/oidc/login/", oidc.sign_in, name="oidc-login"),
    path("accounts/oidc/callback/", oidc.callback, name="oidc-callback"),
    path(
        "accounts/password/",
        auth_views.PasswordChangeView.as_view(success_url="/accounts/password/done/"),
        name="password_change",
    ),
    path(
        "accounts/password/done/",
        auth_views.PasswordChangeDoneView.as_view(),
        name="password_change_done",
    ),
    # The menu's language switcher, and the strings the scripts show (djangojs catalog).
    path("i18n/setlang/", language.set_language, name="set_language"),
    # Built from the catalogs once per process start; browsers revalidate it (304) per page.
    path(
        "i18n/js/",
        last_modified(lambda request, **kwargs: STARTED)(JavaScriptCatalog.as_view()),
        name="javascript-catalog",
    ),
    path("api/", api.urls),
    path("admin/", admin.site.urls),
]

handler400 = "robotide.security.bad_request"
handler404 = "robotide.api.page_not_found"
