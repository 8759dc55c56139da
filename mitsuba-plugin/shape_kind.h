/* shape_kind.h: how a shape defines a diffraction material's tracks
 * (diffraction.cpp, frame_rotation): through its uv parametrisation, as
 * Mitsuba's disk does (polar uv), or not at all (a mesh without texture
 * coordinates); and the tracks' direction at a surface point. No physics.
 */
#pragma once

#include <mitsuba/render/shape.h>

#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <typeinfo>

NAMESPACE_BEGIN(mitsuba)
NAMESPACE_BEGIN(diffraction_detail)

/// How a shape defines the tracks
enum ShapeKind : uint32_t {
    UvShape = 0,      // uv parametrisation (rectangle, meshes with uv, ...; or no shape)
    PolarDisk = 1,    // Mitsuba's disk: u = radius, v = angle / 2 pi
    MeshWithoutUv = 2
};

/// Reads the width of a mesh's texture coordinate buffer from its traverse()
/// (mesh.h, whose accessors would tell, needs headers the wheel lacks).
template <typename Float> struct TexcoordProbe : TraversalCallback {
    // Mesh<Float, Spectrum>::FloatStorage (InputFloat is float)
    using FloatStorage = DynamicBuffer<dr::replace_scalar_t<Float, float>>;
    size_t width = 0;
    bool seen = false;
    void put_value(std::string_view name, void *value, uint32_t,
                   const std::type_info &type) override {
        if (name == "vertex_texcoords" && type == typeid(FloatStorage)) {
            width = dr::width(*(const FloatStorage *) value);
            seen = true;
        }
    }
    void put_object(std::string_view, Object *, uint32_t) override { }
};

/// How one shape defines the tracks. A mesh is probed at every call (scalar
/// variants: per query, a few ns; JIT variants: once per batch and mesh): a
/// cache keyed by the shape's address would go stale when a freed mesh's
/// address is reused.
template <typename Float, typename Spectrum>
uint32_t shape_kind(const Shape<Float, Spectrum> *shape) {
    if (!shape)
        return UvShape;
    uint32_t type = shape->shape_type();
    if (type == +ShapeType::Disk)
        return PolarDisk;
    if (type == +ShapeType::Mesh) {
        TexcoordProbe<Float> probe;
        const_cast<Shape<Float, Spectrum> *>(shape)->traverse(&probe);
        if (probe.seen && probe.width == 0)
            return MeshWithoutUv;
    }
    return UvShape;
}

/// Why a material with tracks cannot render on a mesh without texture
/// coordinates (`tracks`: the tracks the user set, null when not set;
/// `mesh`: its id, may be empty)
inline std::string mesh_without_uv_message(const char *tracks, const std::string &mesh) {
    std::string where = std::string(" on a mesh without texture coordinates") +
                        (mesh.empty() ? "" : " (\"" + mesh + "\")");
    const char *lacks = ", which such a mesh lacks (Mitsuba gives each triangle its own). Give "
                        "the mesh uv coordinates, or use a disk or rectangle shape.";
    if (!tracks)
        return "an anisotropic material (a grating, brushed metal)" + where +
               ": its direction on the surface is defined through the uv parametrisation "
               "(along dp/du; with tracks = \"concentric\", around a uv centre)" + lacks;
    return std::string("tracks = \"") + tracks + "\"" + where +
           ": the tracks' direction is defined through the uv parametrisation (linear "
           "tracks follow dp/du, concentric ones circle a uv centre)" + lacks;
}

/// The direction (c, s) of the tracks in the local (xy) plane before the
/// twist, for linear tracks (the shading tangent; a disk: its object x
/// axis) or concentric ones (radial from the uv centre (center_u,
/// center_v); a disk: from C = (2 center_u - 1, 2 center_v - 1) in object
/// units). `disk`: the lanes on Mitsuba's disk (polar uv). Degenerate lanes
/// (the centre, no uv derivatives) take the shading tangent.
template <typename SurfaceInteraction, typename Mask, typename ScalarFloat>
auto track_direction(const SurfaceInteraction &si, const Mask &disk, bool linear,
                     ScalarFloat center_u, ScalarFloat center_v) {
    using Vector3f = std::decay_t<decltype(si.wi)>;
    using Float = std::decay_t<decltype(si.uv.x())>;
    // A disk's uv is polar: u = r, v = phi / 2 pi, dp_du = M e_r and
    // dp_dv = 2 pi r M e_phi (M: its to_world); its object point is
    // (r cos phi, r sin phi).
    Float r = si.uv.x();
    auto [sin_phi, cos_phi] = dr::sincos(dr::TwoPi<Float> * si.uv.y());
    Vector3f e_phi_world =
        si.dp_dv * dr::select(r > 1e-7f, dr::rcp(dr::TwoPi<Float> * r), 0.f);
    Vector3f dir;
    if (linear) {
        // Generic: the shading tangent; disk: its object x axis
        Vector3f disk_x = si.dp_du * cos_phi - e_phi_world * sin_phi;
        dir = dr::select(disk, si.sh_frame.to_local(disk_x), Vector3f(1.f, 0.f, 0.f));
    } else {
        // Radial: from the centre to the point. Generic: the displacement
        // dp_du du + dp_dv dv (exact for planar uv maps); disk: M (P - C)
        // with C = (2 center_u - 1, 2 center_v - 1) in object units.
        Float cx = 2.f * center_u - 1.f, cy = 2.f * center_v - 1.f;
        Float c_r = cx * cos_phi + cy * sin_phi, c_phi = cy * cos_phi - cx * sin_phi;
        Vector3f disk_r = si.dp_du * (r - c_r) - e_phi_world * c_phi;
        Vector3f uv_r = si.dp_du * (si.uv.x() - center_u) +
                        si.dp_dv * (si.uv.y() - center_v);
        dir = si.sh_frame.to_local(dr::select(disk, disk_r, uv_r));
    }
    Float len = dr::sqrt(dr::square(dir.x()) + dr::square(dir.y()));
    Mask ok = len > 1e-20f && dr::isfinite(len);
    Float inv = dr::select(ok, dr::rcp(len), 0.f);
    // Degenerate (the centre, no uv derivatives): the shading tangent
    Float c0 = dr::select(ok, dir.x() * inv, 1.f),
          s0 = dr::select(ok, dir.y() * inv, 0.f);
    return std::make_pair(c0, s0);
}

/// A vector in the core's frame, whose x axis is (c, s, 0) of the local
/// frame, and back.
template <typename Vector3f, typename Float>
Vector3f to_core(const Vector3f &w, const Float &c, const Float &s) {
    return { c * w.x() + s * w.y(), -s * w.x() + c * w.y(), w.z() };
}
template <typename Vector3f, typename Float>
Vector3f from_core(const Vector3f &v, const Float &c, const Float &s) {
    return { c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z() };
}

/// JIT variants: the id of a registered shape that carries `bsdf` and is a
/// mesh without texture coordinates ("" for none): recorded code cannot look
/// at its lanes, so every such shape is checked while it is recorded.
template <typename Shape, typename BSDF> std::string registered_mesh_without_uv(const BSDF *bsdf) {
    const char *variant = Shape::Variant, *domain = Shape::Domain;
    uint32_t bound = jit_registry_id_bound(variant, domain);
    for (uint32_t id = 1; id <= bound; ++id) {
        auto *shape = (const Shape *) jit_registry_ptr(variant, domain, id);
        if (shape && shape->bsdf() == bsdf && shape_kind(shape) == MeshWithoutUv)
            return std::string(shape->id());
    }
    return "";
}

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
