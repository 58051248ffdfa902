//! The OpenAPI 3.1 description served at `/openapi.json`, generated from
//! the handlers' annotations and the wire types of `curvenet_schema::wire`.

use curvenet_schema::wire::{
    AdjustmentSpec, BakeRequest, BakeResponse, BinaryArray, BinaryFrameHeader, BinaryResponseHeader, BindingOptions,
    BindingRequest, BindingResponse, BindingStats, BindingTimings, BlendShapeMode, BlendShapeSpec, CageSpec, CageStats,
    CurvenetSkinSpec, CurvenetSpec, DeformRequest, DeformResponse, ErrorBody, ErrorDetails, FrameBatchRequest,
    FrameBatchResponse, FrameRequest, FrameResponse, HealthResponse, InbetweenSpec, SegmentAt, SegmentId, SkeletonSpec,
    SkinMethod, SkinSpec, TouchAt, Warning,
};
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};

use crate::binary::BinaryFrames;
use crate::handlers::{bake, batches, bindings, deform, frames, operations};
use crate::viewer;

struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "curvenet",
        description = "Curve-driven character mesh deformation (profile curves, de Goes et al. 2022) as a service. \
                       Bindings are cached by content hash; frames deform a cached binding. Errors are \
                       `{code, message, details}` with stable snake_case codes; `details` names the elements \
                       the error is about (curvenet, spline, segment, sample, control_point, face, vertex, frame, ...), \
                       absent fields omitted. When the server has a token, every route \
                       but /healthz and /readyz needs `Authorization: Bearer <token>`."
    ),
    paths(
        bindings::create_binding,
        bindings::get_binding,
        bindings::delete_binding,
        frames::post_frames,
        batches::post_frames_batch,
        deform::deform,
        bake::bake,
        operations::healthz,
        operations::readyz,
        operations::metrics,
        openapi_json,
        viewer::stages,
        viewer::stage,
        viewer::stage_frame,
        viewer::stage_frame_adjusted,
        viewer::stage_export,
        viewer::stage_refusal,
        viewer::viewer_data,
        viewer::viewer_frame,
    ),
    components(schemas(
        BindingRequest, CurvenetSpec, BlendShapeSpec, InbetweenSpec, BindingOptions, BindingResponse, BindingStats,
        BindingTimings, Warning, SegmentAt, SegmentId, TouchAt, FrameRequest, FrameResponse, AdjustmentSpec, SkinSpec, SkeletonSpec, CageSpec, CageStats, CurvenetSkinSpec, SkinMethod, FrameBatchRequest, FrameBatchResponse, BlendShapeMode,
        DeformRequest, DeformResponse, BakeRequest, BakeResponse, ErrorBody, ErrorDetails, HealthResponse, BinaryArray,
        BinaryFrameHeader, BinaryResponseHeader, BinaryFrames,
        viewer::ViewerStages, viewer::CageView, viewer::ViewerStageInfo, viewer::ViewerStageBinding, viewer::ViewerData, viewer::MeshView,
        viewer::CutView, viewer::CurvenetView, viewer::ViewerFrame, viewer::PoseView, viewer::RestView,
        viewer::ViewerRefusal, viewer::SketchView, viewer::Highlight, viewer::ViewerAdjustment,
        viewer::ViewerAdjustRequest, viewer::ViewerExportRequest,
    )),
    modifiers(&BearerAuth),
    tags(
        (name = "bindings", description = "Bind a mesh to its curvenets (cached by content hash)"),
        (name = "frames", description = "Deform frames of a binding"),
        (name = "bake", description = "Bake a shot on the server's file system"),
        (name = "viewer", description = "Read-only geometry for the browser viewer at /viewer"),
        (name = "operations", description = "Health, readiness, metrics, this document"),
    )
)]
struct ApiDoc;

/// The OpenAPI 3.1 document of the service.
pub fn openapi() -> utoipa::openapi::OpenApi {
    ApiDoc::openapi()
}

/// `GET /openapi.json`.
#[utoipa::path(get, path = "/openapi.json", tag = "operations", security(("bearer" = [])),
    responses((status = 200, description = "This API, OpenAPI 3.1")))]
pub(crate) async fn openapi_json() -> axum::Json<utoipa::openapi::OpenApi> {
    axum::Json(openapi())
}
