"""Routes of the classroom's pages: a teacher's classes, and sign-up with a join code."""

from django.urls import path

from classroom import views_classes as views

urlpatterns = [
    path("classroom/", views.class_list, name="class-list"),
    path("classroom/<int:group_id>/", views.class_detail, name="class-detail"),
    path("classroom/<int:group_id>/students/add", views.class_add_students, name="class-add"),
    path("classroom/<int:group_id>/sheet", views.class_sheet, name="class-sheet"),
    path("classroom/<int:group_id>/join-code", views.class_join_code, name="class-join-code"),
    path("classroom/<int:group_id>/robots", views.class_robots, name="class-robots"),
    path("classroom/<int:group_id>/worlds", views.class_worlds, name="class-worlds"),
    path(
        "classroom/<int:group_id>/students/<int:user_id>/",
        views.student_detail,
        name="class-student",
    ),
    path(
        "classroom/<int:group_id>/students/<int:user_id>/password",
        views.student_new_password,
        name="class-student-password",
    ),
    path(
        "classroom/<int:group_id>/students/<int:user_id>/remove",
        views.student_remove,
        name="class-student-remove",
    ),
    path("accounts/join/", views.join, name="join"),
]
