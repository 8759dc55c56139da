/* shape_kind.h: how a shape defines a diffraction material's tracks
 * (diffraction.cpp, frame_rotation): through its uv parametrisation, as
 * Mitsuba's disk does (polar uv), or not at all (a mesh without texture
 * coordinates). No physics.
 */
#pragma once

#include <mitsuba/render/shape.h>

#include <string_view>
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

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
